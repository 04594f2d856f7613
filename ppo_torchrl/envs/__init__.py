"""Envs and their env side: building an env (make.py, Gymnasium ids and env=legged; playground.py, EnvPool's
Playground tasks), the one owner of env-side state (state.py, rows.py, positions.py), the observation layout and
normalization, config values, MJCF facts and filming. Light on purpose: what imports a room here pays only for it."""
