"""A strip of frames from a video, side by side, for docs/: <out>/<video name>_strip.png.

    .venv/bin/python benchmarks/video_strip.py docs/quadruped_climb.mp4 [more.mp4 ...] [--frames 6] [--width 240]
        [--rate HZ] [--out DIR]

Takes --frames frames evenly over the video (the first and the last included), each scaled to --width
pixels, labelled with its time. Evaluate's videos play in real time, so the video's time is simulated
time; --rate gives the frames per simulated second of a video written at another speed (e.g. 50 for a
frame per 50 Hz control step written at 30 fps). --out defaults to the video's folder.
"""

import argparse
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
from PIL import Image, ImageDraw, ImageFont


def video_strip(video: Path, out: Path, frames: int = 6, width: int = 240, rate: float = 0.0) -> Path:
    reader = imageio.get_reader(video)
    fps = reader.get_meta_data()["fps"]
    count = reader.count_frames()
    picks = set(np.linspace(0, count - 1, min(frames, count)).round().astype(int).tolist())
    images = {i: image for i, image in enumerate(reader) if i in picks}  # one pass, keeping the picks only
    reader.close()
    font = ImageFont.load_default(size=14)
    tiles = []
    for i in sorted(images):
        tile = Image.fromarray(images[i])
        tile = tile.resize((width, round(tile.height * width / tile.width)), Image.LANCZOS)
        draw = ImageDraw.Draw(tile)
        label = f"t = {i / (rate or fps):.1f} s"
        box = draw.textbbox((6, 4), label, font=font)
        draw.rectangle((box[0] - 3, box[1] - 2, box[2] + 3, box[3] + 2), fill=(0, 0, 0))
        draw.text((6, 4), label, fill=(255, 255, 255), font=font)
        tiles.append(np.asarray(tile))
    path = out / f"{video.stem}_strip.png"
    strip = Image.fromarray(np.concatenate(tiles, axis=1))  # 256 colours, dithered: ~half the bytes, same to the eye
    strip.quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.FLOYDSTEINBERG).save(path, optimize=True)
    return path


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("videos", nargs="+", type=Path)
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--width", type=int, default=240, help="of each frame, in pixels")
    parser.add_argument("--rate", type=float, default=0.0, help="frames per simulated second (default: the fps)")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    for video in args.videos:
        png = video_strip(video, args.out or video.parent, args.frames, args.width, args.rate)
        print(f"{png}: {png.stat().st_size / 1000:.0f} KB")
