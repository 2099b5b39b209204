"""RGB frames -> H.264 MP4, the same bytes for the same frames wherever and whenever it runs.

Every video the project writes (the LeRobot export, evaluation videos, episode renders) goes
through `H264Writer`, so one rule holds for all: same frames and settings, same file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

# One encoder thread: x264's frame threading makes the bitstream depend on the thread count (the
# machine's cores). cpu-independent: x264's assembly for the macroblock-tree rate control reads a
# value from the stack it never wrote (valgrind: "use of uninitialised value ... created by a stack
# allocation" in libx264, gone with mbtree off), so the bitstream depended on what earlier code
# had left on the C stack: at 48x36, a cold numba compilation before the first video gave
# different MP4s in each of 3 processes for the same frames; with the option 3 of 3 are the bytes
# of a process that compiled nothing. It also keeps CPUs with other SIMD sets on the same bytes.
# Its cost at 160x120 (16 episodes of the default dataset): the same PSNR (37.70 dB median), 0.2%
# fewer bytes, about 4% more encoding time.
DETERMINISTIC_X264 = {"threads": "1", "x264-params": "cpu-independent=1"}


class H264Writer:
    """Frames of one size (RGB uint8 [H, W, 3]) -> an H.264 MP4 (yuv420p, which browsers play),
    frame i at pts i / fps. The size is the first frame's, cut to even numbers (yuv420p needs them);
    `crf` is x264's constant quality (lower: better, larger), `b_frames` None keeps the preset's.
    Use as a context manager, or call `close()`: the file is complete only then."""

    def __init__(self, path: str | Path, fps: int, crf: int = 20, preset: str = "medium",
                 b_frames: int | None = None):
        from navcore.optional import require

        av = require("av", "writing an episode video")

        self.path = Path(path)
        self.fps = fps
        self.options = {"crf": str(crf), "preset": preset, **DETERMINISTIC_X264}
        if b_frames is not None:
            self.options["bf"] = str(b_frames)
        self.container = av.open(str(self.path), mode="w", format="mp4")
        self.stream = None

    def add(self, rgb: np.ndarray) -> None:
        import av  # imported by __init__ (require)

        if self.stream is None:
            self.stream = self.container.add_stream("libx264", rate=self.fps)
            h, w = rgb.shape[:2]
            self.stream.width, self.stream.height, self.stream.pix_fmt = w - w % 2, h - h % 2, "yuv420p"
            # set after the size: PyAV opens the codec with these
            self.stream.codec_context.options = dict(self.options)
        rgb = rgb[: self.stream.height, : self.stream.width]
        for p in self.stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")):
            self.container.mux(p)

    def close(self) -> None:
        if self.stream is not None:
            for p in self.stream.encode():
                self.container.mux(p)
        self.container.close()

    def __enter__(self) -> H264Writer:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()
        else:  # no flush: the caller's error stands, its atomic write drops the file
            self.container.close()
