"""Evaluate, video, export, loggers, progress and report on real short runs."""

import json
import re
import time
import subprocess
import sys

import imageio.v2 as imageio
import pytest
import torch
from matplotlib.container import ErrorbarContainer
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl import evaluate, export, report
from ppo_torchrl.run.checkpoint import load_policy
from ppo_torchrl.evaluate import evaluate_policy
from ppo_torchrl.envs.filming import EpisodeProgress
from ppo_torchrl.run.loggers import Progress
from ppo_torchrl.trainer import Trainer

from conftest import ROOT, run_cli


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """One short InvertedPendulum run shared by the tests of this module (TanhNormal head)."""
    from conftest import TINY, compose_config

    run_dir = tmp_path_factory.mktemp("run")
    cfg = compose_config(["env=InvertedPendulum-v4", *TINY, "policy=tanh_normal", "eval.every_frames=256",
                          "eval.episodes=1", "eval.video=true"])
    Trainer(cfg, run_dir).train()
    return run_dir


def test_video_during_training(trained_run):
    videos = sorted((trained_run / "videos").glob("eval_*.mp4"))
    assert [v.name for v in videos] == ["eval_0000000256.mp4", "eval_0000000512.mp4"]
    assert all(v.stat().st_size > 1000 for v in videos)


def test_training_videos_film_the_episodes_and_length_asked(tmp_path):
    """eval.video_episodes / eval.video_length: the second episode only, at most 0.2 s (25 fps: 5 frames)."""
    from conftest import TINY, compose_config

    cfg = compose_config(["env=InvertedPendulum-v4", *TINY, "eval.every_frames=256", "eval.episodes=2",
                          "eval.final_episodes=0", "eval.background=false", "eval.video=true",
                          "eval.video_episodes=[1]", "eval.video_length=0.2"])
    trainer = Trainer(cfg, tmp_path)
    trainer.train()
    video = trainer.last_eval["video"]
    assert video["episodes"] == [1] and video["fps"] == 25
    frames = imageio.get_reader(tmp_path / "videos" / "eval_0000000256.mp4").count_frames()
    assert frames == video["frames"] == min(5, trainer.last_eval["lengths"][1])


def test_evaluate_cli_writes_json_and_video(trained_run):
    result = run_cli(f"run={trained_run}", "episodes=2", "video=true", module="ppo_torchrl.evaluate")
    assert result.returncode == 0, result.stderr[-2000:]
    assert "return" in result.stdout and "+-" in result.stdout
    assert re.search(r"^eval: 1/2 episodes, \d+ s elapsed, ETA \d+ s$", result.stderr, re.M)  # progress, off a TTY
    data = json.loads((trained_run / "eval" / "eval.json").read_text())
    assert len(data["returns"]) == 2 and data["episodes"] == 2 and data["checkpoint"] == "best"
    video = trained_run / "eval" / "best.mp4"
    assert video.stat().st_size > 1000
    assert video.read_bytes()[4:8] == b"ftyp"  # an mp4 container
    # real time: InvertedPendulum's control runs at 25 Hz, so a frame per step, written at 25 fps
    assert data["video"]["episodes"] == [0] and data["video"]["every"] == 1 and data["video"]["fps"] == 25
    reader = imageio.get_reader(video)
    assert reader.count_frames() == data["video"]["frames"] == data["lengths"][0]
    assert reader.get_meta_data()["fps"] == 25 and "25 fps" in result.stdout


def test_evaluate_films_the_episodes_asked_up_to_the_length_asked(trained_run, tmp_path):
    result = run_cli(f"run={trained_run}", "episodes=3", "video_episodes=1,2", "video_length=0.2", f"out={tmp_path}",
                     module="ppo_torchrl.evaluate")  # video=true implied
    assert result.returncode == 0, result.stderr[-2000:]
    data = json.loads((tmp_path / "eval.json").read_text())
    lengths, video = data["lengths"], data["video"]
    assert video["episodes"] == ([1] if lengths[1] >= 5 else [1, 2])  # 0.2 s at 25 fps: 5 frames in all
    assert video["frames"] == imageio.get_reader(tmp_path / "best.mp4").count_frames() == min(5, lengths[1] + lengths[2])
    for args, expected in [(["video_episodes=3"], "video_episodes=3: expected episode numbers in 0..2"),
                           (["video_episodes=0,x"], "video_episodes=0,x"),
                           (["video_length=0"], "video_length=0: expected the video's length in seconds > 0")]:
        result = run_cli(f"run={trained_run}", "episodes=3", *args, f"out={tmp_path}", module="ppo_torchrl.evaluate")
        assert result.returncode == 2 and "Traceback" not in result.stderr
        assert expected in result.stderr.strip().splitlines()[-1]


def test_video_follows_the_robot_at_real_time(tmp_path):
    """Gymnasium's Hopper, moved 10 m along x while filmed: it stays in frame (its `track` camera), and a
    97-step episode at 125 Hz (a frame per 5 steps, 25 fps: 30 at most) lasts its 0.776 s of simulated time."""
    from conftest import compose_config

    from ppo_torchrl.envs.make import gym_make_kwargs, make_gym_env
    from ppo_torchrl.envs.filming import Filming

    cfg = compose_config(["env=Hopper-v4"])
    assert gym_make_kwargs(cfg.env, "rgb_array")["camera_name"] == "track"
    env = make_gym_env(cfg.env, "rgb_array", width=160, height=120)
    film = Filming(tmp_path / "hopper.mp4", env, which=[0])
    env.reset(seed=0)
    callback = film.start(0)  # the reset: step 0
    for _ in range(96):  # steps 1..96 of 97: torchrl's rollout calls back after each step but the last
        env.step(env.action_space.sample() * 0)
        env.unwrapped.data.qpos[0] += 0.1
        callback()
    video = film.close()
    env.close()
    assert (video["every"], video["fps"], video["frames"]) == (5, 25, 19)
    assert abs(video["seconds"] / (97 * env.unwrapped.dt) - 1) < 0.05
    frames = [frame for frame in imageio.get_reader(tmp_path / "hopper.mp4")]  # (list() asks its len: inf)
    assert len(frames) == 19
    rgb = frames[-1].astype(int)  # the hopper's orange body, 9.6 m from where it started
    orange = (rgb[..., 0] > 90) & (rgb[..., 0] - rgb[..., 1] > 35) & (rgb[..., 1] - rgb[..., 2] > 15)
    assert orange.sum() > 20  # 74 here; 0 from the free camera Gymnasium renders from unless told


def test_eval_progress_only_when_asked_or_slow(trained_run, capsys):
    cfg, ac, state = load_policy(trained_run, "last")
    evaluate_policy(cfg, ac, state["normalization"]["obs"], 2, seed=0)  # as training calls it: a short eval is silent
    assert capsys.readouterr().err == ""
    evaluate_policy(cfg, ac, state["normalization"]["obs"], 2, seed=0, progress=True)
    lines = capsys.readouterr().err.splitlines()  # after the first episode, then at most every 10 s
    assert len(lines) == 1 and re.fullmatch(r"eval: 1/2 episodes, \d+ s elapsed, ETA \d+ s", lines[0])

    slow = EpisodeProgress(4, progress=None, tty=False)
    slow.start -= 6  # an eval running for 6 s already: past the quiet period, so it reports
    slow.update(1)
    assert capsys.readouterr().err == "eval: 1/4 episodes, 6 s elapsed, ETA 18 s\n"
    filmed = EpisodeProgress(4, progress=True, tty=False)
    filmed.start -= 6  # 4 of the 6 s spent filming episode 1, and 1.5 s of filming still to come
    filmed.update(1, film_s=4.0, film_left_s=1.5)
    assert capsys.readouterr().err == "eval: 1/4 episodes, 6 s elapsed, ETA 8 s\n"  # (6 - 4) x 3 + 1.5
    terminal = EpisodeProgress(2, progress=True, tty=True)
    terminal.update(1)
    terminal.update(2)  # one updating line, erased when the eval ends
    assert capsys.readouterr().err == "\r\x1b[Keval: 1/2 episodes, 0 s elapsed, ETA 0 s\r\x1b[K"


def test_filming_talks_while_it_renders(tmp_path, capsys):
    """Issue 49: a filmed episode says how far it is while its frames render (off a terminal at most every
    10 s, the first after 10 s), with the filming left: the terminal is never silent for a whole episode."""
    from conftest import compose_config

    from ppo_torchrl.envs.make import make_gym_env
    from ppo_torchrl.envs.filming import Filming

    env = make_gym_env(compose_config(["env=InvertedPendulum-v4"]).env, "rgb_array", width=64, height=48)
    film = Filming(tmp_path / "p.mp4", env, which=[0])
    shown = EpisodeProgress(3, progress=None, tty=False)
    film.on_frame = lambda: shown.filming(0, film, [])
    env.reset(seed=0)
    callback = film.start(0)
    for _ in range(4):
        callback()
    assert capsys.readouterr().err == ""  # quiet for the first seconds
    shown.start = time.perf_counter() - 12  # filming for 12 s now (and the next frame's render time: a busy
    callback()                                # machine may take a second for it)
    line = capsys.readouterr().err
    assert re.fullmatch(r"eval: 0/3 episodes, filming episode 0: 6 frames \(0\.2 s of video\), 1[23] s elapsed, "
                        r"filming left ~\d+ s\n", line), line  # 1000 steps allowed: ~994 frames left to film
    callback()
    assert capsys.readouterr().err == ""  # the next after another 10 s
    film.close()
    env.close()


def test_evaluate_bad_input_is_one_line(trained_run, capsys):
    """One case as a process (the exit code and stderr a shell sees), the rest through the same error path
    in-process (errors.guarded, which the entry point runs main under)."""
    from ppo_torchrl.errors import guarded

    result = run_cli("run=/nonexistent", module="ppo_torchrl.evaluate")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "run=/nonexistent: no such dir" in result.stderr.strip().splitlines()[-1]
    for args, expected in [([f"run={ROOT / 'conf'}"], "not a ppo_torchrl run dir (no checkpoints/)"),
                           ([f"run={trained_run}", "episodes=many"], "expected a int"),
                           ([f"run={trained_run}", "checkpoint=nope.pt"], "does not exist")]:
        capsys.readouterr()
        with pytest.raises(SystemExit) as exit_:
            guarded(evaluate.main, args)
        lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert exit_.value.code == 2 and len(lines) == 1 and expected in lines[0], lines


def test_exported_policy_matches_the_actor_and_runs_without_torchrl(trained_run, tmp_path):
    path = export.main([f"run={trained_run}", "checkpoint=last"])
    cfg, ac, state = load_policy(trained_run, "last")
    policy = torch.jit.load(str(path))
    raw = torch.randn(5, 4) * 2
    stats = state["normalization"]["obs"]
    norm = ((raw.double() - torch.as_tensor(stats["mean"])) / torch.sqrt(torch.as_tensor(stats["var"]) + 1e-8))
    td = TensorDict({"observation": norm.float().clamp(-10, 10)}, [5])
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        expected = ac.actor(td)["action"]
    torch.testing.assert_close(policy(raw), expected, atol=1e-5, rtol=1e-5)
    assert policy(raw[0]).shape == (1,) and policy(raw.view(5, 1, 4)).shape == (5, 1, 1)  # any batch shape

    script = tmp_path / "deploy.py"
    script.write_text(
        "import sys\n"
        "for name in ('torchrl', 'tensordict', 'ppo_torchrl'):\n"
        "    sys.modules[name] = None  # importing any of them now fails\n"
        "import gymnasium as gym, torch\n"
        f"policy = torch.jit.load({str(path)!r})\n"
        "env = gym.make('InvertedPendulum-v4')\n"
        "obs, _ = env.reset(seed=0)\n"
        "total, done = 0.0, False\n"
        "while not done:\n"
        "    action = policy(torch.as_tensor(obs, dtype=torch.float32)).numpy()\n"
        "    assert env.action_space.contains(action), action\n"
        "    obs, r, term, trunc, _ = env.step(action)\n"
        "    total, done = total + r, term or trunc\n"
        "print('episode return', total)\n"
    )
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "episode return" in out.stdout


@pytest.mark.parametrize("logger, pattern", [
    ("csv", "logs/csv/scalars/lr.csv"),
    ("tensorboard", "logs/tensorboard/events.out.tfevents.*"),
    ("wandb", "logs/wandb/offline-run-*/run-*.wandb"),
    ("mlflow", "logs/mlruns/*/*/metrics/lr"),
])
def test_each_logger_writes_its_files(tiny_cfg, tmp_path, monkeypatch, logger, pattern):
    monkeypatch.setenv("WANDB_MODE", "offline")
    Trainer(tiny_cfg(f"logger={logger}"), tmp_path).train()
    files = list(tmp_path.glob(pattern))
    assert files and all(f.stat().st_size > 0 for f in files), pattern
    if logger == "tensorboard":
        from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

        events = EventAccumulator(str(files[0].parent))
        events.Reload()
        assert [e.step for e in events.Scalars("lr")] == [256, 512]
    if logger == "mlflow":
        steps = [line.split()[2] for line in files[0].read_text().splitlines()]
        assert steps == ["256", "512"]


def test_progress_plain_lines_off_a_terminal(capsys):
    progress = Progress(total_frames=1000, start_frames=0, every_s=3600, tty=False)
    row = {"frames": 500, "sps": 250.0, "train/return_last100": 12.5}
    progress.update(row, 500, force=False)  # first call prints
    progress.update({**row, "frames": 750}, 250, force=False)  # within every_s: silent
    progress.update({**row, "frames": 1000}, 250, force=True)
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2 and "frames       500/1000" in lines[0] and "eta" in lines[0]


def test_report_png(trained_run):
    out = report.main([str(trained_run)])[0]
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000


def test_report_marks_each_eval_and_says_what_each_train_curve_averages(tmp_path):
    # InvertedPendulum-like: short episodes first, then 1000-step ones, two per iteration; one eval
    (tmp_path / "metrics.csv").write_text(
        "iteration,frames,train/episodes,train/episode_return,train/return_last100,eval/return_mean,eval/return_std\n"
        "1,2048,90,10.0,10.0,,\n"
        "2,4096,8,200.0,25.0,,\n"
        "3,6144,2,1000.0,44.0,950.0,30.0\n")
    fig = report.run_figure(tmp_path)
    ax = fig.axes[0]
    [eval_bars] = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    point = eval_bars.lines[0]
    assert point.get_marker() == "o" and point.get_linestyle() == "None"  # a marker, no connecting line
    assert (list(point.get_xdata()), list(point.get_ydata())) == ([6144], [950])
    assert eval_bars.lines[2][0].get_segments()[0][:, 1].tolist() == [920, 980]  # its +- std bar
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "train: mean of the episodes finished in each iteration",
        "train: mean of the last 100 finished episodes (at the end they span the last 6,144 frames, so it lags)",
        "eval: deterministic, mean +- std over its episodes",
    ]
    import matplotlib.pyplot as plt  # after run_figure chose the Agg backend

    plt.close(fig)
    assert report.plot_run(tmp_path).read_bytes()[:4] == b"\x89PNG"



def test_an_early_best_checkpoint_is_named_as_such(trained_run, tmp_path, capsys):
    """best.pt older than last.pt (a joystick run's best can be its 1M-frame stander of 20M): loading it says so and
    names checkpoint=last; a best.pt of the last frame, or checkpoint=last itself, says nothing."""
    import shutil

    from ppo_torchrl.run.checkpoint import load, load_policy, save

    run = tmp_path / "run"
    shutil.copytree(trained_run, run, ignore=shutil.ignore_patterns("eval", "videos"))
    last = load(run / "checkpoints" / "last.pt")
    save(run / "checkpoints" / "best.pt", {**last, "frames": 256, "best_eval_return": 12.5})
    load_policy(run, "best")
    err = capsys.readouterr().err
    assert f"note: best.pt is the policy at 256 of the run's {last['frames']:,} frames (its highest in-training eval " \
           "return, 12.5); checkpoint=last is the final one" in err
    load_policy(run, "last")
    save(run / "checkpoints" / "best.pt", last)
    load_policy(run, "best")
    assert "best.pt is the policy at" not in capsys.readouterr().err


def test_checkpoint_fallbacks_say_what_was_loaded(trained_run, tmp_path):
    """Issue 49: best without a best.pt is last.pt, labelled (last) in the line, eval.json and the video's
    name; a checkpoint that is not there names those that are."""
    import shutil

    run = tmp_path / "run"
    shutil.copytree(trained_run, run, ignore=shutil.ignore_patterns("eval"))  # other tests' evals left out
    (run / "checkpoints" / "best.pt").unlink(missing_ok=True)
    result = run_cli(f"run={run}", "episodes=1", "video=true", "video_length=0.1", module="ppo_torchrl.evaluate")
    assert result.returncode == 0, result.stderr[-2000:]
    assert f"note: {run} has no best.pt (no eval saved one): using last.pt" in result.stderr
    assert "frames (last)" in result.stdout and (run / "eval" / "last.mp4").is_file()
    assert not (run / "eval" / "best.mp4").exists()
    assert json.loads((run / "eval" / "eval.json").read_text())["checkpoint"] == "last"
    shutil.copy(run / "checkpoints" / "last.pt", run / "checkpoints" / "best.pt")
    (run / "checkpoints" / "last.pt").unlink()
    result = run_cli(f"run={run}", "checkpoint=last", module="ppo_torchrl.evaluate")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert "checkpoint=last:" in lines[0] and "best.pt (checkpoint=best)" in lines[0], lines[0]


def test_a_filmed_floor_reaches_past_where_the_best_policies_hop():
    """Issue 49: Gymnasium's Hopper floor is drawn to 20 m and the zoo Hopper ends at ~21 m: filmed, the floor
    is drawn far wider, the same checker under the robot at 30 m as at the start, and the physics unchanged."""
    import mujoco
    from conftest import compose_config

    from ppo_torchrl.envs.make import make_gym_env

    cfg = compose_config(["env=Hopper-v4"])
    env = make_gym_env(cfg.env, "rgb_array", width=160, height=120)
    plain = make_gym_env(cfg.env)
    env.reset(seed=0)
    bottom = {}
    for x in (0.0, 30.0):
        env.unwrapped.data.qpos[0] = x
        mujoco.mj_forward(env.unwrapped.model, env.unwrapped.data)
        bottom[x] = env.render()[-10:].reshape(-1, 3).astype(float)
    env.close()
    assert abs(bottom[30.0].mean(0) - bottom[0.0].mean(0)).max() < 5  # floor, not the sky (34, 44, 52 before)
    assert bottom[30.0].std() > 40  # the checker's squares
    filmed, unfilmed = env.unwrapped.model, plain.unwrapped.model
    assert filmed.geom_size[0, 0] == 500 and unfilmed.geom_size[0, 0] == 20  # only the drawn size changed
    plain.close()
