"""Loggers: `logger=csv|none` through torchrl.record.loggers, plus the run's own metrics.csv.

Every run writes `metrics.csv` (one row per iteration, fixed columns) whatever logger is chosen:
reports, sweeps and resume read it. The `logger` group adds an external logger on top.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Dict, List

from ppo_torchrl.errors import ConfigError

LOGGERS = ("csv", "none")


def make_logger(cfg, run_dir: Path):
    if cfg.name not in LOGGERS:
        raise ConfigError(f"logger='{cfg.name}' is not known; use one of {', '.join(LOGGERS)}")
    if cfg.name == "none":
        return None
    from torchrl.record.loggers import CSVLogger

    return CSVLogger(exp_name="csv", log_dir=str(run_dir / "logs"))


class MetricsFile:
    """Append-only CSV with a fixed header; columns missing from a row are left empty."""

    def __init__(self, path: Path, columns: List[str], append: bool = False):
        self.path = Path(path)
        append = append and self.path.exists()
        self._file = open(self.path, "a" if append else "w", newline="")
        self._writer = csv.DictWriter(self._file, fieldnames=columns, extrasaction="ignore")
        if not append:
            self._writer.writeheader()

    def write(self, row: Dict[str, float]) -> None:
        self._writer.writerow({k: _fmt(v) for k, v in row.items()})
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def _fmt(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def truncate_logs(run_dir: Path, frames: int) -> None:
    """Drop rows logged after `frames` (metrics.csv and the CSV logger's scalars): on resume the
    run goes on from its checkpoint, and what was logged past it is logged again."""
    metrics = Path(run_dir) / "metrics.csv"
    if metrics.exists():
        lines = metrics.read_text().splitlines(keepends=True)
        col = lines[0].rstrip("\n").split(",").index("frames") if lines else 0
        keep = lines[:1] + [l for l in lines[1:] if int(l.split(",")[col]) <= frames]
        metrics.write_text("".join(keep))
    for scalars in (Path(run_dir) / "logs").glob("*/scalars/**/*.csv"):
        lines = scalars.read_text().splitlines(keepends=True)
        scalars.write_text("".join(l for l in lines if int(l.split(",")[0]) <= frames))
