"""navcore.io.video.H264Writer: frames in, the same frames decoded, the same bytes every time."""
import numpy as np
import pytest

from benchmarks.gpu.render_gpu import psnr
from navcore.io.video import H264Writer


def _frames(n=24, h=45, w=63):
    """A smooth moving pattern (what rendered views look like to a codec): odd sizes on purpose."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    out = []
    for k in range(n):
        r = 127 + 100 * np.sin((x + 2 * k) / 9.0)
        g = 127 + 100 * np.cos((y - k) / 7.0)
        b = 127 + 80 * np.sin((x + y + 3 * k) / 11.0)
        out.append(np.stack([r, g, b], -1).round().astype(np.uint8))
    return out


def _decoded(path):
    import av

    with av.open(str(path)) as c:
        s = c.streams.video[0]
        return [f.to_ndarray(format="rgb24") for f in c.decode(s)], s.codec_context.name, float(s.average_rate)


def test_frames_come_back_cut_to_even_sizes_at_the_rate_given(tmp_path):
    frames = _frames()
    with H264Writer(tmp_path / "a.mp4", fps=5, crf=18) as v:
        for f in frames:
            v.add(f)
    dec, codec, rate = _decoded(tmp_path / "a.mp4")
    assert codec == "h264" and rate == 5.0 and len(dec) == len(frames)
    assert dec[0].shape == (44, 62, 3)  # 45 x 63 cut to even (yuv420p)
    for a, b in zip(dec, frames):
        assert psnr(a / 255.0, b[:44, :62] / 255.0) > 30  # seen: about 35 (yuv420p halves the chroma)


def test_same_frames_same_bytes_and_a_failed_write_raises_its_own_error(tmp_path):
    frames = _frames(n=12)
    for name in ("a.mp4", "b.mp4"):
        with H264Writer(tmp_path / name, fps=10, crf=23, b_frames=0) as v:
            for f in frames:
                v.add(f)
    assert (tmp_path / "a.mp4").read_bytes() == (tmp_path / "b.mp4").read_bytes()
    with pytest.raises(RuntimeError, match="renderer broke"):
        with H264Writer(tmp_path / "c.mp4", fps=10) as v:
            v.add(frames[0])
            raise RuntimeError("renderer broke")
