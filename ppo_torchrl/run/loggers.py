"""Loggers: `logger=csv|tensorboard|wandb|mlflow|none` through torchrl.record.loggers, plus the run's own metrics.csv.

Every run writes `metrics.csv` (one row per iteration, fixed columns) whatever logger is chosen:
reports, sweeps and resume read it. The `logger` group adds an external logger on top.
"""

from __future__ import annotations

import csv
import io
import math
import sys
import time
from collections import deque
from pathlib import Path
from typing import Dict, List, Optional

from ppo_torchrl.errors import ConfigError

LOGGERS = ("csv", "tensorboard", "wandb", "mlflow", "none")
# metrics.csv columns, in order; a row leaves the ones it lacks empty.
COLUMNS = [
    "iteration", "frames", "time_s", "sps", "lr",
    "train/episode_return", "train/episode_length", "train/return_last100", "train/episodes",
    "eval/return_mean", "eval/return_std", "eval/length_mean",
    "loss/objective", "loss/critic", "loss/entropy", "loss/total",
    "train/entropy", "train/approx_kl", "train/clipfrac", "train/explained_variance", "train/grad_norm",
    "policy/loc_mean", "policy/scale_mean", "train/value_mean", "train/advantage_std",
]
EXTRA = {"tensorboard": "tensorboard", "wandb": "wandb", "mlflow": "mlflow-skinny"}
# MuJoCo warnings about a model file we ship or Gymnasium does, which the user can do nothing about
MUJOCO_NOISE = ("settotalmass",)  # in Gymnasium's half_cheetah.xml, which MuJoCo now deprecates


def job_tag() -> str:
    """`[#3] ` in a sweep's job 3 (Hydra's job number, as its launch lines give it), so that the lines of jobs
    running in parallel say whose they are; '' in a single run."""
    try:
        from hydra.core.hydra_config import HydraConfig
    except ImportError:
        return ""
    if not HydraConfig.initialized() or HydraConfig.get().mode.name != "MULTIRUN":
        return ""
    return f"[#{HydraConfig.get().job.num}] "


def quiet_mujoco() -> None:
    """MuJoCo warnings on stderr as one line each, without those in MUJOCO_NOISE (which MuJoCo's own handler
    prints once per model compiled, and appends to MUJOCO_LOG.TXT in the working dir)."""
    import mujoco

    def warn(message: str) -> None:
        if not any(noise in message for noise in MUJOCO_NOISE):
            print(f"MuJoCo warning: {message.strip()}", file=sys.stderr, flush=True)

    mujoco.set_mju_user_warning(warn)


def make_logger(cfg, run_dir: Path, run_name: str):
    """A torchrl.record.loggers logger writing under the run dir; none of them needs a network:
    wandb runs offline (sync later with `wandb sync`), mlflow uses a local file store."""
    if cfg.name == "none":
        return None
    try:
        if cfg.name == "csv":
            from torchrl.record.loggers import CSVLogger

            return CSVLogger(exp_name="csv", log_dir=str(run_dir / "logs"))
        if cfg.name == "tensorboard":
            from torchrl.record.loggers import TensorboardLogger

            return TensorboardLogger(exp_name="tensorboard", log_dir=str(run_dir / "logs"))
        if cfg.name == "wandb":
            import os

            from torchrl.record.loggers import WandbLogger

            os.environ.setdefault("WANDB_SILENT", "true")
            return WandbLogger(exp_name=run_name, offline=True, save_dir=str(run_dir / "logs"),
                               project=cfg.project, log_env_packages=False)
        import os

        from torchrl.record.loggers import MLFlowLogger

        # A local file store, as asked; recent mlflow wants this opt-in for the file backend.
        os.environ.setdefault("MLFLOW_ALLOW_FILE_STORE", "true")
        return MLFlowLogger(exp_name=cfg.project, tracking_uri=(run_dir / "logs" / "mlruns").resolve().as_uri(),
                            tags={"run": run_name})
    except ImportError as exc:
        raise ConfigError(f"logger={cfg.name} needs the '{EXTRA[cfg.name]}' package: "
                          f"pip install -e '.[loggers]' ({exc})") from exc


def close_logger(logger) -> None:
    """Flush and finish the logger's run (wandb and mlflow keep one open)."""
    experiment = getattr(logger, "experiment", None)
    for name in ("finish", "close"):  # wandb run, tensorboard SummaryWriter
        if hasattr(experiment, name):
            getattr(experiment, name)()
            return
    if type(logger).__name__ == "MLFlowLogger":
        import mlflow

        mlflow.end_run()


class MetricsFile:
    """Append-only CSV with a fixed header; columns missing from a row are left empty."""

    def __init__(self, path: Path, columns: List[str], append: bool = False):
        self.path = Path(path)
        append = append and self.path.exists()
        if append:  # a resumed run keeps its file's header (one written by an older build may have fewer columns)
            with open(self.path, newline="") as f:
                columns = next(csv.reader(f), None) or columns
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
    run goes on from its checkpoint, and what was logged past it is logged again. The rows kept keep their bytes
    (no newline translation: the csv module ends rows with \\r\\n), so the file stays a prefix of what it was
    and a record taken mid-run stays a prefix of the finished log (records.compress)."""
    from ppo_torchrl.internals import csv_logger_files
    from ppo_torchrl.run.rundir import atomic_write_bytes

    def keep_rows(path: Path, header: bool) -> None:  # the file replaced whole: a kill leaves the old rows or the kept
        lines = path.read_bytes().decode().splitlines(keepends=True)
        head, rows = (lines[:1], lines[1:]) if header else ([], lines)
        col = head[0].rstrip("\r\n").split(",").index("frames") if head else 0
        kept = "".join(head + [l for l in rows if int(l.split(",")[col]) <= frames])
        atomic_write_bytes(path, lambda f: f.write(kept.encode()))

    metrics = Path(run_dir) / "metrics.csv"
    if metrics.exists():
        keep_rows(metrics, header=True)
    for scalars in csv_logger_files(run_dir):
        keep_rows(scalars, header=False)


def amend_last_row(path: Path, frames: int, values: Dict[str, float]) -> bool:
    """Fill `values` into the row of metrics.csv logged at `frames` (the last): the final eval of a run that
    resume= finishes joins its last iteration's row. The file is replaced whole (a kill: the old or the new).
    False when the last row is not at `frames` (nothing written)."""
    from ppo_torchrl.run.rundir import atomic_write_bytes

    if not Path(path).exists():
        return False
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if len(rows) < 2 or "frames" not in rows[0] or rows[-1][rows[0].index("frames")] != str(frames):
        return False
    header = rows[0]
    for key, value in values.items():
        if key in header and len(rows[-1]) == len(header):
            rows[-1][header.index(key)] = _fmt(value)
    text = io.StringIO(newline="")
    csv.writer(text).writerows(rows)
    atomic_write_bytes(Path(path), lambda f: f.write(text.getvalue().encode()))
    return True


class Progress:
    """A tqdm bar (frames, SPS, recent return, ETA) on a terminal; plain periodic lines otherwise,
    which read well in CI logs and batch-job output files."""

    def __init__(self, total_frames: int, start_frames: int, every_s: float, tty: Optional[bool] = None):
        self.total = total_frames
        self.every_s = every_s
        self.tty = sys.stdout.isatty() if tty is None else tty
        self.tag = job_tag()  # a sweep job's lines start with its number
        self._last = -math.inf  # the first update always prints
        self._seen: deque = deque(maxlen=20)  # (time, frames) of the recent updates: the ETA's rate
        self.bar = None
        if self.tty:
            from tqdm import tqdm

            self.bar = tqdm(total=total_frames, initial=start_frames, unit="frame", unit_scale=True,
                            dynamic_ncols=True, smoothing=0.1, desc=self.tag.strip() or None)

    def update(self, row: dict, frames_done: int, force: bool) -> None:
        stats = {"sps": f"{row['sps']:.0f}"}
        if row.get("train/return_last100") is not None:
            stats["return"] = f"{row['train/return_last100']:.1f}"
        if row.get("eval/return_mean") is not None:
            stats["eval"] = f"{row['eval/return_mean']:.1f}"
        if self.bar is not None:
            self.bar.update(frames_done)
            self.bar.set_postfix(stats, refresh=False)
            if "eval" in stats:
                self.bar.write(f"{self.tag}eval at {row['frames']} frames: {row['eval/return_mean']:.1f} +- "
                               f"{row['eval/return_std']:.1f}")
            return
        now = time.perf_counter()
        step = now - self._seen[-1][0] if self._seen else 0.0  # the last iteration's time: the next comes about then
        self._seen.append((now, row["frames"]))
        # now, when the next line would come later than every_s after the last one: lines at most every_s apart
        # (a longer iteration: a line each)
        if force or "eval" in stats or now - self._last + step > self.every_s:
            self._last = now
            parts = [f"frames {row['frames']:>9d}/{self.total}", f"sps {row['sps']:6.0f}"]
            if "return" in stats:
                parts.append(f"return(last100) {row['train/return_last100']:8.1f}")
            if "eval" in stats:
                parts.append(f"eval {row['eval/return_mean']:8.1f} +- {row['eval/return_std']:.1f}")
            eta = self.eta_s()
            parts.append(f"eta {eta / 60:5.1f} min" if eta is not None else "eta after warm-up")
            print(self.tag + " | ".join(parts), file=sys.stderr, flush=True)  # with start/done lines (and tqdm)

    def eta_s(self) -> Optional[float]:
        """Seconds left at the rate of the recent updates (the first one, which holds the compile warm-up
        and the envs' start, is never in it); None before there are two."""
        if len(self._seen) < 2:
            return None
        (t0, f0), (t1, f1) = self._seen[0], self._seen[-1]
        return (self.total - f1) * (t1 - t0) / max(f1 - f0, 1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
