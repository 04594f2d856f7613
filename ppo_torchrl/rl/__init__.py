"""The RL core: the actor and critic, the losses, advantage estimation, the minibatch step, and the policy on raw
arrays an evaluation runs."""
