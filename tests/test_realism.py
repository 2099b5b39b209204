"""The realism benchmark's measures (benchmarks/captures/realism.py): known answers on constructed
frames, and a classifier that separates what differs and cannot separate what does not."""
import numpy as np
import pytest

from benchmarks.captures import realism


def test_near_black_top_counts_the_upper_third_only():
    img = np.full((30, 40, 3), 200, np.uint8)
    img[:10] = 0  # the upper third black: a room without a ceiling
    assert realism.near_black_top(img) == 1.0
    img[:10] = 200
    img[20:] = 0  # black below the upper third is not counted
    assert realism.near_black_top(img) == 0.0
    img[:5] = 10  # half the upper third darker than 16 in every channel
    assert realism.near_black_top(img) == pytest.approx(0.5)


def test_colour_entropy_known_answers():
    one = np.full((8, 8, 3), 77, np.uint8)
    assert realism.colour_entropy(one) == 0.0
    two = one.copy()
    two[:4] = 250  # two colours, half each: one bit
    assert realism.colour_entropy(two) == pytest.approx(1.0)
    rng = np.random.default_rng(0)
    noise = rng.integers(0, 256, (256, 256, 3), dtype=np.uint8)
    assert realism.colour_entropy(noise) == pytest.approx(9.0, abs=0.02)  # 512 bins, all equally likely


def test_gradient_energy_zero_on_flat_and_grows_with_contrast():
    flat = np.full((20, 20, 3), 128, np.uint8)
    assert realism.gradient_energy(flat) == 0.0
    step = flat.copy()
    step[:, 10:] = 255
    strong = step.copy()
    strong[:, :10] = 0
    assert 0 < realism.gradient_energy(step) < realism.gradient_energy(strong)


def test_spectrum_slope_of_one_over_f_noise_is_minus_two():
    """Noise whose amplitude falls as 1/f has power falling as 1/f^2: slope -2."""
    rng = np.random.default_rng(1)
    n = 256
    fy, fx = np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij")
    f = np.hypot(fx, fy)
    f[0, 0] = 1.0
    spec = (rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))) / f
    y = np.real(np.fft.ifft2(spec))
    y = (y - y.min()) / (y.max() - y.min())
    img = np.repeat((y * 255).astype(np.uint8)[..., None], 3, axis=2)
    assert realism.spectrum_slope(img) == pytest.approx(-2.0, abs=0.3)


def test_depth_histogram_bins_and_nothing_hit():
    d = np.array([[0.2, 0.7, 1.5, 2.5], [4.0, 6.0, 0.0, np.inf]])
    h = realism.depth_histogram(d)
    assert h.sum() == pytest.approx(1.0) and len(h) == len(realism.DEPTH_BINS) - 1
    assert h.tolist() == pytest.approx([1 / 8, 1 / 8, 1 / 8, 1 / 8, 1 / 8, 1 / 8, 2 / 8])


def test_classifier_separates_what_differs_and_not_what_does_not():
    rng = np.random.default_rng(2)
    dark = [rng.integers(0, 60, (24, 48, 64, 3), dtype=np.uint8) for _ in range(4)]
    bright = [rng.integers(150, 256, (24, 48, 64, 3), dtype=np.uint8) for _ in range(2)]
    assert realism.classifier_accuracy(dark, bright, seed=0, steps=150) >= 0.95
    noise = lambda: rng.integers(0, 256, (24, 48, 64, 3), dtype=np.uint8)  # noqa: E731 - one distribution
    acc = realism.classifier_accuracy([noise() for _ in range(4)], [noise() for _ in range(2)], seed=0, steps=150)
    assert 0.3 <= acc <= 0.7


def test_standing_poses_keep_the_robots_radius_clear():
    from types import SimpleNamespace

    clearance = np.zeros((20, 30))
    clearance[5:15, 10:20] = 1.0
    cm = SimpleNamespace(clearance=clearance, cell_centers=lambda c: (np.asarray(c)[:, ::-1] + 0.5) * 0.1)
    poses = realism.standing_poses(cm, 0.5, 50, np.random.default_rng(0))
    assert poses.shape == (50, 3)
    cols, rows = (poses[:, 0] / 0.1 - 0.5).round().astype(int), (poses[:, 1] / 0.1 - 0.5).round().astype(int)
    assert (clearance[rows, cols] >= 0.5).all()
    with pytest.raises(ValueError, match="no cell"):
        realism.standing_poses(SimpleNamespace(clearance=np.zeros((3, 3)), cell_centers=None), 0.5, 2,
                               np.random.default_rng(0))
