"""Where the app's config files are: the conf/ dir Hydra composes and the env files in it. A leaf (nothing of the
package, nothing heavy), so that `env=<name>` is checked before torch loads and any module may ask."""

from __future__ import annotations

from pathlib import Path

CONF_DIR = str(Path(__file__).resolve().parent.parent / "conf")


def env_files() -> list[str]:
    """The env ids that have a file in conf/env (plus the generic `gym`)."""
    return sorted(p.stem for p in (Path(CONF_DIR) / "env").glob("*.yaml"))
