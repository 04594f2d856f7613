"""What ships with the package and the repository, named one way wherever a hint lists it: the six Menagerie robots
(ppo_torchrl/assets/menagerie/<robot>/scene.xml, for env=legged), the in-house models (assets/*.xml, for env=mjcf and
the quadruped env files), and the shipped runs (zoo/ and results/: records that evaluate and export only read)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

ASSETS = Path(__file__).resolve().parent / "assets"
REPO = Path(__file__).resolve().parent.parent
SHIPPED_RUNS = ("zoo", "results")  # a run under either is a record: its files are the repository's


def robots() -> List[str]:
    """The shipped Menagerie robots as env.xml_file takes them: ['menagerie/anybotics_anymal_b/scene.xml', ...]."""
    return sorted(f"menagerie/{p.parent.name}/scene.xml" for p in (ASSETS / "menagerie").glob("*/scene.xml"))


def in_house() -> List[str]:
    """The in-house models (env=mjcf, env=quadruped...): ['quadruped.xml', ...]."""
    return sorted(p.name for p in ASSETS.glob("*.xml"))


def models_hint() -> str:
    """The shipped models, for a hint: the six robots for env=legged first, then the in-house ones."""
    return (f"a shipped robot for env=legged: {', '.join(robots())}; or an in-house model: {', '.join(in_house())}")


def shipped_run(directory) -> Optional[Path]:
    """The path of `directory` inside the repository when it is (in) a shipped run folder, zoo/ or results/ (symlinks
    followed), else None: evaluate and export of such a run write under outputs/<that path>/, never into it."""
    path = Path(directory).expanduser().resolve()
    for top in SHIPPED_RUNS:
        root = REPO / top
        if path == root or root in path.parents:
            return path.relative_to(REPO)
    return None
