"""The frames of README's "Modes you can watch": the animated GIFs of modes 1-3 of the default 3RRR at (0, 0, 0)
(what ``fpm-sim modes --animate modeK.gif --mode K`` writes) and the first frame of each (the peak of the motion)
as a PNG.

    python scripts/mode_frames.py --out docs/figures [--gifs out/mode_gifs]

Writes ``mode{1,2,3}_frame.png`` under ``--out`` (and the GIFs under ``--gifs`` when given).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from PIL import Image

import fpm_sim as fs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/figures"), help="folder of the PNG frames")
    parser.add_argument("--gifs", type=Path, help="also keep the GIFs in this folder")
    args = parser.parse_args()
    result = fs.modes(None, fs.Pose(0.0, 0.0, 0.0), n_modes=3)  # the default machine and resolution
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        gifs = args.gifs or Path(tmp)
        gifs.mkdir(parents=True, exist_ok=True)
        for k in (1, 2, 3):
            gif = result.animate(gifs / f"mode{k}.gif", mode=k)
            with Image.open(gif) as im:
                im.seek(0)  # frame 0: a quarter frame before the peak of the motion
                im.convert("RGB").save(args.out / f"mode{k}_frame.png", optimize=True)
            print(f"mode {k}: {result.modes[k - 1].frequency_hz:.2f} Hz -> {args.out / f'mode{k}_frame.png'}")


if __name__ == "__main__":
    main()
