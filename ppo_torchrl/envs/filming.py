"""Filming an eval and saying how far it is: `Filming` writes the chosen episodes into one mp4 in real time
(rendering only the frames it keeps: the frame rate is the cost), `EpisodeProgress` the `eval: 3/10
episodes` line, and while a filmed episode renders, a line at least every EVERY_S seconds.
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from ppo_torchrl.errors import ConfigError

# Videos play in real time at VIDEO_MAX_FPS or less: a frame every k-th control step, k the smallest that
# keeps rate / k <= VIDEO_MAX_FPS (50 Hz control: every 2nd step, 25 fps), written at rate / k fps. Only
# those frames are rendered (~0.1 s each on an idle CPU), so the frame rate is the filming cost.
VIDEO_MAX_FPS = 30
VIDEO_SIZE = (480, 360)
QUIET_S = 5.0  # progress=None (training's evals): no line unless the eval is still running after this
EVERY_S = 10.0  # off a terminal, a plain progress line at most this often


class EpisodeProgress:
    """`eval: 3/10 episodes, 12 s elapsed, ETA 28 s` on stderr after an episode: on a terminal an
    updating line, erased when the eval ends; otherwise a plain line at most every EVERY_S seconds.
    The ETA leaves filming out of the time per episode: film_s, the time spent rendering so far, counts
    once; film_left_s, the filming still to come (Filming.left_s), is added."""

    def __init__(self, total: int, progress: Optional[bool], tty: Optional[bool] = None, elsewhere: int = 0):
        self.total, self.start, self.last, self.shown = total, time.perf_counter(), -math.inf, False
        # an eval shared with the background eval process: its episodes are said, not counted as ours
        self.of = f"{total} episodes" + (f" (and {elsewhere} in the background eval process)" if elsewhere else "")
        self.quiet_s = math.inf if progress is False else 0.0 if progress else QUIET_S
        self.tty = sys.stderr.isatty() if tty is None else tty

    def update(self, done: int, film_s: float = 0.0, film_left_s: float = 0.0) -> None:
        now = time.perf_counter()
        elapsed = now - self.start
        if self.tty and done == self.total:
            if self.shown:  # the result line comes next, in its place
                print("\r\x1b[K", end="", file=sys.stderr, flush=True)
            return
        if elapsed < self.quiet_s or (not self.tty and now - self.last < EVERY_S):
            return
        eta = max(elapsed - film_s, 0.0) / done * (self.total - done) + film_left_s
        self._show(now, f"eval: {done}/{self.of}, {elapsed:.0f} s elapsed, ETA {eta:.0f} s")

    def filming(self, done: int, film: "Filming", lengths: Sequence[int]) -> None:
        """After each filmed frame: `eval: 0/10 episodes, filming episode 0: 120 frames (4.8 s of video),
        31 s elapsed, filming left ~90 s`, at most every second on a terminal, else every EVERY_S seconds
        (rendering is the slow part of an eval: the terminal is never silent for long while it runs)."""
        now = time.perf_counter()
        elapsed = now - self.start
        quiet = now - (self.last if self.shown else self.start)
        if elapsed < min(self.quiet_s, EVERY_S) or quiet < (1.0 if self.tty else EVERY_S):
            return
        left = film.left_s(done, lengths)
        self._show(now, f"eval: {done}/{self.of}, filming episode {film.filmed[-1]}: {film.frames} "
                        f"frames ({film.frames / film.fps:.1f} s of video), {elapsed:.0f} s elapsed"
                        + (f", filming left ~{left:.0f} s" if left else ""))

    def _show(self, now: float, line: str) -> None:
        print("\r\x1b[K" + line if self.tty else line, end="" if self.tty else "\n", file=sys.stderr, flush=True)
        self.last, self.shown = now, True


class Filming:
    """Films episodes `which` (indices into run_episodes' seeds) of `env`, a Gymnasium env made with
    render_mode="rgb_array", into one mp4 at real-time speed: a frame per `every` control steps (VIDEO_*
    above), written at fps = control rate / every; at most `length_s` seconds of video. An episode of
    n steps shows the states after steps 0 (the reset) .. n-1, the frame of each run of `every` steps
    taken at its middle: round(n / every) frames, so its duration is n * dt within every / 2 steps."""

    def __init__(self, path: Path, env, which: Sequence[int], length_s: Optional[float] = None):
        unwrapped = env.unwrapped
        dt = getattr(unwrapped, "dt", None) or 1.0 / unwrapped.metadata.get("render_fps", VIDEO_MAX_FPS)
        rate = 1.0 / dt  # control steps per simulated second
        self.every = max(1, math.ceil(rate / VIDEO_MAX_FPS - 1e-9))
        self.fps = rate / self.every
        self.path, self.env, self.which = path, env, sorted(set(which))
        self.max_frames = math.inf if length_s is None else max(1, round(length_s * self.fps))
        self.frames, self.spent_s, self.filmed, self._writer = 0, 0.0, [], None
        self._frames_before, self._first_s = 0, 0.0
        self.limit = getattr(env.spec, "max_episode_steps", None)  # an episode's steps at most (None: unknown)
        self.on_frame = None  # called after each frame (EpisodeProgress.filming: the terminal is never silent)

    def start(self, episode: int):
        """Right after episode `episode`'s reset: the rollout callback that films it (torchrl calls it after
        each step but the last), the reset being step 0; None when this episode is not filmed."""
        if episode not in self.which or self.frames >= self.max_frames:
            return None
        self.filmed.append(episode)
        self._frames_before = self.frames
        steps = itertools.count(0)

        def callback(*_):
            if next(steps) % self.every == self.every // 2 and self.frames < self.max_frames:
                self._take()
        callback()
        return callback

    def _take(self) -> None:
        start = time.perf_counter()
        try:
            frame = self.env.render()
        except Exception as exc:
            if self.frames:
                raise
            raise ConfigError(f"rendering is unavailable here ({type(exc).__name__}: {str(exc).splitlines()[0]}); "
                              "set MUJOCO_GL=egl (or osmesa) or run with video=false") from exc
        if self._writer is None:
            import imageio.v2 as imageio

            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = imageio.get_writer(self.path, fps=self.fps, macro_block_size=8)
        self._writer.append_data(frame)
        self.frames += 1
        self.spent_s += time.perf_counter() - start
        if self.frames == 1:  # the renderer's start-up: not the cost of the frames to come
            self._first_s = self.spent_s
        if self.on_frame is not None:
            self.on_frame()

    def left_s(self, done: int, lengths: Sequence[int]) -> float:
        """The filming still to come after `done` episodes: at this video's cost per frame so far, the
        episodes left to film, each as long as the mean episode so far (within the length cap)."""
        typical = np.mean(lengths) if lengths else self.limit  # no episode ended yet: as long as allowed
        if not self.frames or not typical:
            return 0.0
        left = sum(e >= done for e in self.which) * math.ceil(typical / self.every)
        if self.filmed and self.filmed[-1] == done:  # the episode being filmed: what it has not filmed yet
            left -= min(self.frames - self._frames_before, math.ceil(typical / self.every))
        per_frame = (self.spent_s - self._first_s) / (self.frames - 1) if self.frames > 1 else self.spent_s
        return per_frame * max(min(left, self.max_frames - self.frames), 0)

    def close(self) -> Optional[dict]:
        """Finish the mp4; what it holds (None when no frame was taken)."""
        if self._writer is None:
            return None
        self._writer.close()
        self._writer = None
        return {"path": str(self.path), "episodes": self.filmed, "frames": self.frames, "fps": self.fps,
                "every": self.every, "seconds": self.frames / self.fps}


def video_line(video: dict) -> str:
    """'video: <path> (episode 0: 8.0 s at 31.25 fps, a frame per 4 control steps of 125 Hz: real time)'."""
    every = f"a frame per {video['every']} control steps of" if video["every"] > 1 else "a frame per control step,"
    return (f"video: {video['path']} (episode{'s' * (len(video['episodes']) > 1)} "
            f"{','.join(map(str, video['episodes']))}: {video['seconds']:.1f} s at {video['fps']:.4g} fps, "
            f"{every} {video['fps'] * video['every']:.4g} Hz: real time)")
