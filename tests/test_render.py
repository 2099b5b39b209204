"""Rendering: the camera convention, the CPU renderer's known answers, and gsplat agreement (GPU)."""
import math

import numpy as np
import pytest
import torch

from benchmarks.gpu.render_gpu import psnr
from navcore.gaussians.model import GaussianScene
from navcore.gaussians.sh import C0
from navcore.render import Renderer
from navcore.render.camera import camera_to_world, intrinsics, viewmats

W, H, HFOV = 64, 48, 90.0


def to_cam(pose, height, pitch, p):
    vm = viewmats(np.array([pose]), height, pitch)[0].astype(np.float64)
    return vm[:3, :3] @ np.asarray(p, float) + vm[:3, 3]


def test_camera_convention():
    # facing +x: ahead is +z, the robot's right (-y) is +x, up (+z) is -y (OpenCV axes)
    assert np.allclose(to_cam((1, 2, 0), 0.88, 0, (2, 2, 0.88)), (0, 0, 1), atol=1e-6)
    assert np.allclose(to_cam((1, 2, 0), 0.88, 0, (1, 1, 0.88)), (1, 0, 0), atol=1e-6)
    assert np.allclose(to_cam((1, 2, 0), 0.88, 0, (1, 2, 1.88)), (0, -1, 0), atol=1e-6)
    # heading +y
    assert np.allclose(to_cam((1, 2, math.pi / 2), 0.88, 0, (1, 3, 0.88)), (0, 0, 1), atol=1e-6)
    # pitched 30 degrees down: a floor point ahead on the optical axis
    d = 0.88 / math.tan(math.radians(30))
    assert np.allclose(to_cam((0, 0, 0), 0.88, -30, (d, 0, 0)), (0, 0, math.hypot(d, 0.88)), atol=1e-6)
    m = camera_to_world(0.3, -0.2, 1.0, 0.5, 10)
    assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(m[:3, :3]), 1)
    k = intrinsics(640, 480, 90)
    assert k[0, 0] == pytest.approx(320) and k[0, 2] == 320 and k[1, 2] == 240


@pytest.mark.parametrize("pitch", [0.0, -15.0, 25.0])
def test_batched_viewmats_invert_camera_to_world(pitch):
    """viewmats' closed form is the inverse of each pose's camera_to_world (np.linalg.inv, the
    reference): the same float32 bytes for a level camera (every embodiment's default, so renders and
    stored goal images do not move), within 1e-6 when pitched."""
    rng = np.random.default_rng(1)
    poses = np.c_[rng.uniform(-30, 30, (500, 2)), rng.uniform(-4, 4, 500)]
    ref = np.stack([np.linalg.inv(camera_to_world(x, y, yaw, 0.88, pitch)) for x, y, yaw in poses]).astype(np.float32)
    got = viewmats(poses, 0.88, pitch)
    assert got.dtype == np.float32 and got.shape == (500, 4, 4)
    if pitch == 0:
        assert np.array_equal(got, ref)
    np.testing.assert_allclose(got, ref, atol=1e-6)
    assert viewmats(np.zeros((0, 3)), 0.88, pitch).shape == (0, 4, 4)


def scene(means, sigmas, opacities, rgbs) -> GaussianScene:
    n = len(means)
    sh = ((np.asarray(rgbs, float) - 0.5) / C0)[:, None, :]
    return GaussianScene(np.asarray(means, float), np.tile([1.0, 0, 0, 0], (n, 1)),
                         np.log(np.repeat(np.asarray(sigmas, float)[:, None], 3, 1)),
                         np.log(np.asarray(opacities) / (1 - np.asarray(opacities))), sh)


def render(gs, pose=(0, 0, 0), backend="cpu"):
    vm = viewmats(np.array([pose]), 0.0)
    k = intrinsics(W, H, HFOV)[None]
    return Renderer(gs, backend).render(vm, k, W, H)


def expected_alpha(opacity, sigma, z, px, py):
    """Alpha of an isotropic Gaussian on the optical axis at the centre of pixel (px, py)."""
    f = (W / 2) / math.tan(math.radians(HFOV / 2))
    var = (f * sigma / z) ** 2 + 0.3
    d2 = (px + 0.5 - W / 2) ** 2 + (py + 0.5 - H / 2) ** 2
    return min(0.999, opacity * math.exp(-0.5 * d2 / var))


CPU_BACKENDS = pytest.mark.parametrize("backend", ["cpu", "torch"])


@CPU_BACKENDS
def test_single_gaussian_known_answer(backend):
    gs = scene([(2.0, 0, 0)], [0.05], [0.8], [(0.2, 0.4, 0.6)])
    out = render(gs, backend=backend)
    a = expected_alpha(0.8, 0.05, 2.0, W // 2, H // 2)
    assert out.alpha[0, H // 2, W // 2].item() == pytest.approx(a, rel=1e-5)
    assert out.rgb[0, H // 2, W // 2].numpy() == pytest.approx(np.array([0.2, 0.4, 0.6]) * a, rel=1e-4)
    assert out.depth[0, H // 2, W // 2].item() == pytest.approx(2.0, rel=1e-6)
    # symmetric about the image centre, nothing far away, nothing behind the camera
    al = out.alpha[0].numpy()
    assert np.allclose(al, al[::-1, ::-1], atol=1e-6) and al[0, 0] == 0
    assert render(gs, pose=(0, 0, math.pi), backend=backend).alpha.max().item() == 0


@CPU_BACKENDS
def test_compositing_order_and_expected_depth(backend):
    near, far = (1.5, 0, 0), (3.0, 0, 0)
    gs = scene([far, near], [0.1, 0.05], [0.9, 0.5], [(0, 0, 1), (1, 0, 0)])
    out = render(gs, backend=backend)
    a1 = expected_alpha(0.5, 0.05, 1.5, W // 2, H // 2)
    a2 = expected_alpha(0.9, 0.1, 3.0, W // 2, H // 2)
    w1, w2 = a1, (1 - a1) * a2
    px = out.rgb[0, H // 2, W // 2].numpy()
    assert px == pytest.approx([w1, 0, w2], rel=1e-4, abs=1e-6)
    assert out.depth[0, H // 2, W // 2].item() == pytest.approx((w1 * 1.5 + w2 * 3.0) / (w1 + w2), rel=1e-5)
    # input order does not matter: depth decides
    swapped = render(scene([near, far], [0.05, 0.1], [0.5, 0.9], [(1, 0, 0), (0, 0, 1)]), backend=backend)
    assert torch.equal(swapped.rgb, out.rgb)
    # a far plane between them leaves the far one out (its mean is deeper): the near one alone
    vm, k = viewmats(np.array([(0, 0, 0)]), 0.0), intrinsics(W, H, HFOV)[None]
    cut = Renderer(gs, backend).render(vm, k, W, H, far=2.0)
    alone = render(scene([near], [0.05], [0.5], [(1, 0, 0)]), backend=backend)
    assert torch.allclose(cut.rgb, alone.rgb, atol=1e-6) and torch.allclose(cut.alpha, alone.alpha, atol=1e-6)
    assert cut.depth[0, H // 2, W // 2].item() == pytest.approx(1.5, rel=1e-6)


def test_depth_ranks_are_the_stable_order_of_the_depths():
    # the merge sort under SMALL_SORT candidates and the radix sort above give the same ranks:
    # ascending depth, ties in index order (gsplat's)
    from navcore.render import cpu_fast

    r = np.random.default_rng(6)
    for n in (0, 1, 7, cpu_fast.SMALL_SORT - 1, cpu_fast.SMALL_SORT, 30000):
        z = r.choice(r.uniform(0.01, 50.0, max(n // 3, 1)).astype(np.float32), n)  # many ties
        ref = np.empty(n, np.int32)
        ref[np.argsort(z, kind="stable")] = np.arange(n)
        assert np.array_equal(cpu_fast._depth_ranks(z), ref), n


@CPU_BACKENDS
def test_pixel_stops_when_transmittance_is_spent(backend):
    # ten nearly opaque layers: after three the transmittance is below 1e-4, the rest add nothing
    xs = [1.0 + 0.1 * i for i in range(10)]
    gs = scene([(x, 0, 0) for x in xs], [0.3] * 10, [0.99] * 10, [(1, 1, 1)] * 10)
    out = render(gs, backend=backend)
    a = [expected_alpha(0.99, 0.3, x, W // 2, H // 2) for x in xs]
    T, acc, dsum = 1.0, 0.0, 0.0
    for ai, x in zip(a, xs):
        if T * (1 - ai) <= 1e-4:
            break
        acc, dsum, T = acc + ai * T, dsum + ai * T * x, T * (1 - ai)
    assert out.alpha[0, H // 2, W // 2].item() == pytest.approx(acc, rel=1e-5)
    assert out.depth[0, H // 2, W // 2].item() == pytest.approx(dsum / acc, rel=1e-5)
    assert out.depth[0, H // 2, W // 2].item() < 1.25  # the far layers never show


def room_views(small_scene, n_rooms=None):
    gs = small_scene.gaussians.transformed(np.linalg.inv(small_scene.transform))
    rooms = np.array(small_scene.layout.rooms)[:n_rooms]
    return gs, np.array([[(r[0] + r[2]) / 2, (r[1] + r[3]) / 2, a] for r in rooms for a in (0.0, 2.0)])


@pytest.mark.parametrize("size", [(160, 120), (320, 240)])
def test_compiled_renderer_matches_the_torch_reference(small_scene, size):
    # two independent implementations of gsplat's rules (the torch one was checked against gsplat on
    # an H100): the compiled renderer's culling, radix sort, tile binning and per-row spans must not
    # change the image
    from navcore.nav.embodiment import Embodiment
    from navcore.render.camera import embodiment_camera

    gs, poses = room_views(small_scene, 2)
    vm, k, w, h = embodiment_camera(Embodiment(), poses, *size)
    a, b = Renderer(gs, "torch").render(vm, k, w, h), Renderer(gs, "cpu").render(vm, k, w, h)
    assert b.alpha.mean() > 0.5  # the views see the rooms
    for i in range(len(vm)):
        assert psnr(a.rgb[i].numpy(), b.rgb[i].numpy()) >= 80
    assert torch.allclose(a.alpha, b.alpha, atol=5e-3)
    both = (a.alpha > 0.5) & (b.alpha > 0.5)
    assert torch.median((a.depth - b.depth).abs()[both]).item() <= 1e-4


def test_the_renderers_llvm_intrinsics_reach_the_compiled_function():
    """`_wide_vectors` writes "prefer-vector-width"="512" into the calling function's definition
    (through llvmlite's attribute set, which only accepts attributes it knows: a llvmlite upgrade
    that changes the set would silently drop the attribute or fail to compile); `_prefetch` emits
    llvm.prefetch on the element's address and changes no value."""
    import numba

    from navcore.render import cpu_fast

    wide, prefetch = cpu_fast._wide_vectors, cpu_fast._prefetch

    def body(x, rows):
        wide()
        s = 0.0
        for k in range(rows.shape[0]):
            if k + 2 < rows.shape[0]:
                prefetch(x, rows[k + 2] * 3)
            s += x[rows[k], 1]
        return s

    f = numba.njit(cache=False)(body)
    x = np.arange(30.0).reshape(10, 3)
    assert f(x, np.array([9, 0, 4, 4], np.int32)) == 28 + 1 + 13 + 13
    ir = "\n".join(f.inspect_llvm().values())
    assert '"prefer-vector-width"="512"' in ir
    assert "call void @llvm.prefetch" in ir


def test_compiled_renderer_is_deterministic_across_thread_counts(small_scene):
    import numba

    from navcore.nav.embodiment import Embodiment
    from navcore.render.camera import embodiment_camera

    gs, poses = room_views(small_scene, 1)
    vm, k, w, h = embodiment_camera(Embodiment(), poses, 160, 120)
    r = Renderer(gs, "cpu")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = r.render(vm, k, w, h)
    finally:
        numba.set_num_threads(before)
    many = r.render(vm, k, w, h)
    assert torch.equal(one.rgb, many.rgb) and torch.equal(one.depth, many.depth)


@pytest.mark.gpu
def test_cpu_renderer_matches_gsplat(small_scene):
    pytest.importorskip("gsplat")
    if not torch.cuda.is_available():
        pytest.skip("needs CUDA")
    from navcore.nav.embodiment import Embodiment
    from navcore.render.camera import embodiment_camera

    gs = small_scene.gaussians.transformed(np.linalg.inv(small_scene.transform))
    rooms = np.array(small_scene.layout.rooms)
    poses = np.array([[(r[0] + r[2]) / 2, (r[1] + r[3]) / 2, a] for r in rooms for a in (0.0, 2.0)])
    vm, k, w, h = embodiment_camera(Embodiment(), poses, 160, 120)
    a = Renderer(gs, "gsplat").render(vm, k, w, h)
    b = Renderer(gs, "cpu").render(vm, k, w, h)
    assert psnr(a.rgb.cpu().numpy(), b.rgb.numpy()) >= 35
    both = (a.alpha.cpu() > 0.5) & (b.alpha > 0.5)
    assert torch.median((a.depth.cpu() - b.depth).abs()[both]).item() <= 0.01
    # the far plane (the episodes' blind-view test uses it) leaves out the same Gaussians in both
    a, b = Renderer(gs, "gsplat").render(vm, k, w, h, far=1.5), Renderer(gs, "cpu").render(vm, k, w, h, far=1.5)
    assert torch.allclose(a.alpha.cpu(), b.alpha, atol=1e-3) and b.alpha.mean() < 0.9 * Renderer(gs, "cpu").render(
        vm, k, w, h).alpha.mean()


def test_feature_rendering_gives_label_weights():
    # two Gaussians side by side with one-hot labels: each half of the image takes its own label
    gs = scene([(2.0, 0.3, 0), (2.0, -0.3, 0)], [0.15, 0.15], [0.95, 0.95], [(0.5, 0.5, 0.5)] * 2)
    feats = np.array([[1.0, 0.0], [0.0, 1.0]], np.float32)
    vm = viewmats(np.array([[0, 0, 0]]), 0.0)
    out = Renderer(gs, "cpu").render(vm, intrinsics(W, H, HFOV)[None], W, H, features=feats)
    lab = out.rgb[0].numpy()
    assert lab.shape == (H, W, 2)
    # +y (left in the image: OpenCV x is the robot's right) holds label 0
    left, right = W // 2 - 5, W // 2 + 5  # the Gaussians' centres project to u = 32 -+ 4.8
    assert lab[H // 2, left, 0] > 0.5 > lab[H // 2, left, 1]
    assert lab[H // 2, right, 1] > 0.5 > lab[H // 2, right, 0]
    assert np.allclose(lab.sum(-1), out.alpha[0].numpy(), atol=1e-5)  # weights add up to the coverage


def test_what_the_compiled_passes_would_read_out_of_bounds_is_refused():
    # an SH-0 scene (the real hall's SPZ) rendered at degree 3 once read the next Gaussians'
    # coefficients, and past the array's end for the last ones: garbage, NaN in some frames
    from navcore.render import cpu_fast

    gs = scene([(2.0, 0.3, 0), (2.0, -0.3, 0)], [0.15, 0.15], [0.95, 0.95], [(0.5, 0.5, 0.5)] * 2)
    for backend in ("cpu", "torch"):
        with pytest.raises(ValueError, match="sh_degree=3 asked for a scene with SH degree 0"):
            Renderer(gs, backend, sh_degree=3)
        with pytest.raises(ValueError, match="sh_degree=-1"):
            Renderer(gs, backend, sh_degree=-1)
        assert Renderer(gs, backend).sh_degree == 0 == Renderer(gs, backend, sh_degree=0).sh_degree
    g = cpu_fast.prepare(gs)
    vm, k = viewmats(np.array([[0, 0, 0]]), 0.0)[0], intrinsics(W, H, HFOV)
    with pytest.raises(ValueError, match="SH degree 0"):
        cpu_fast.render_one(g, vm, k, W, H, 3)
    with pytest.raises(ValueError, match=r"features must be \[2, C\]"):
        cpu_fast.render_one(g, vm, k, W, H, 0, features=np.ones((1, 2), np.float32))
    with pytest.raises(ValueError, match=r"extra must be \[2, C\]"):
        cpu_fast.render_one(g, vm, k, W, H, 0, extra=np.ones(2, np.float32))
    rgb, _, alpha = cpu_fast.render_one(g, vm, k, W, H, 0, extra=np.ones((2, 1), np.float32))
    assert np.allclose(rgb[..., 3], alpha)  # a constant extra channel composites to the coverage


def backends():
    out = ["cpu"]
    if torch.cuda.is_available():
        try:
            import gsplat  # noqa: F401

            out.append("gsplat")
        except ImportError:
            pass
    return out


@pytest.mark.parametrize("backend", backends())
def test_extra_features_ride_along_with_the_colour(backend, small_scene):
    # one pass with extra features gives the plain pass's colour, depth and alpha, and the features'
    # composite equal to a features-only pass
    gs = small_scene.gaussians.transformed(np.linalg.inv(small_scene.transform))
    rooms = np.array(small_scene.layout.rooms)
    poses = np.array([[(r[0] + r[2]) / 2, (r[1] + r[3]) / 2, a] for r in rooms[:2] for a in (0.0, 2.0)])
    vm = viewmats(poses, 1.0)
    k = np.repeat(intrinsics(W, H, HFOV)[None], len(vm), 0)
    ids = small_scene.instance_ids
    feats = np.stack([ids == i for i in np.unique(ids)[:5]], 1).astype(np.float32)
    r = Renderer(gs, backend)
    both, plain, only = r.render(vm, k, W, H, extra=feats), r.render(vm, k, W, H), r.render(vm, k, W, H, features=feats)
    assert both.extra.shape == (len(vm), H, W, feats.shape[1]) and plain.extra is None
    assert torch.allclose(both.rgb, plain.rgb, atol=2e-5) and torch.allclose(both.depth, plain.depth, atol=1e-5)
    assert torch.allclose(both.alpha, plain.alpha, atol=1e-6)
    assert torch.allclose(both.extra, only.rgb, atol=1e-5)


def test_gaussians_behind_a_finished_wall_change_nothing():
    # three layers of nearly opaque Gaussians finish every pixel (T <= 1e-4): whatever lies behind
    # them must leave the image identical to the byte (the compiled renderer skips finished pixels
    # and whole finished rows of a tile without testing their Gaussians)
    g = np.arange(-1.6, 1.61, 0.2)
    wall = [(x, y, z) for x in (1.0, 1.05, 1.1) for y in g for z in g]
    r = np.random.default_rng(3)
    behind = np.column_stack([r.uniform(2, 5, 400), r.uniform(-2, 2, 400), r.uniform(-1.5, 1.5, 400)])
    n1, n2 = len(wall), len(behind)
    only = scene(wall, [0.15] * n1, [0.995] * n1, [(0.8, 0.2, 0.1)] * n1)
    both = scene(np.vstack([wall, behind]), [0.15] * n1 + list(r.uniform(0.01, 0.3, n2)),
                 [0.995] * n1 + list(r.uniform(0.1, 0.99, n2)), [(0.8, 0.2, 0.1)] * n1 + list(r.uniform(0, 1, (n2, 3))))
    a, b = render(only), render(both)
    assert a.alpha.min().item() > 0.99  # the wall covers the view (and its layers spend every pixel's T)
    assert torch.equal(a.rgb, b.rgb) and torch.equal(a.depth, b.depth) and torch.equal(a.alpha, b.alpha)
    # the reference (no skipping of any kind) agrees
    ref = render(both, backend="torch")
    assert torch.allclose(ref.rgb, b.rgb, atol=1e-5) and torch.allclose(ref.depth, b.depth, atol=1e-5)


def test_the_gaussians_the_rasteriser_reads_make_the_same_frame(small_scene):
    # visits (benchmarks.scale.render_cpu --bound): the Gaussians read are the ones a perfect occlusion
    # culling would keep, so rendering them alone gives the frame to the byte; hidden ones are not read
    from navcore.render import cpu_fast

    g = np.arange(-1.6, 1.61, 0.2)
    wall = [(x, y, z) for x in (1.0, 1.05, 1.1) for y in g for z in g]
    r = np.random.default_rng(3)
    behind = np.column_stack([r.uniform(2, 5, 400), r.uniform(-2, 2, 400), r.uniform(-1.5, 1.5, 400)])
    n1 = len(wall)
    gs = scene(np.vstack([wall, behind]), [0.15] * n1 + [0.1] * 400, [0.995] * n1 + [0.9] * 400,
               [(0.8, 0.2, 0.1)] * (n1 + 400))
    vm = viewmats(np.array([[0.0, 0.0, 0.0]]), 0.0)[0]
    k = intrinsics(W, H, HFOV)
    visits = np.zeros((len(gs.means), 2), np.uint8)
    plain = cpu_fast.render_one(cpu_fast.prepare(gs), vm, k, W, H, 0)
    counted = cpu_fast.render_one(cpu_fast.prepare(gs), vm, k, W, H, 0, visits=visits)
    assert all(np.array_equal(a, b) for a, b in zip(plain, counted))
    assert visits[n1:].sum() == 0 and visits[:n1, 1].sum() > 100  # behind the finished wall: never read
    assert np.all(visits[:, 1] <= visits[:, 0])  # a contributor was read
    with pytest.raises(ValueError, match="visits"):
        cpu_fast.render_one(cpu_fast.prepare(gs), vm, k, W, H, 0, visits=np.zeros((3, 2), np.uint8))
    # a realistic scene, robot views in its rooms: the Gaussians read alone give the same bytes
    from navcore.nav.embodiment import Embodiment
    from navcore.render.camera import embodiment_camera

    gen, poses = room_views(small_scene, 2)
    vms, ks, w, h = embodiment_camera(Embodiment(), poses, 160, 120)
    gfull = cpu_fast.prepare(gen)
    for v, kk in zip(vms, ks):
        visits = np.zeros((len(gen.means), 2), np.uint8)
        a = cpu_fast.render_one(gfull, v, kk, w, h, 0, visits=visits)
        read = visits[:, 0] == 1
        assert 0 < read.sum() < len(gen.means)
        b = cpu_fast.render_one(cpu_fast.prepare(gen.subset(read)), v, kk, w, h, 0)
        assert a[2].mean() > 0.5 and all(np.array_equal(x, y) for x, y in zip(a, b))


def test_compiled_renderer_matches_the_torch_reference_with_degree_3_colour():
    # the view-dependent colour (SH degree 3, as the real scenes) evaluated by both renderers
    r = np.random.default_rng(5)
    n = 3000
    gs = GaussianScene(np.column_stack([r.uniform(1.5, 6, n), r.uniform(-3, 3, n), r.uniform(-2, 2, n)]),
                       r.normal(size=(n, 4)), np.log(r.uniform(0.02, 0.3, (n, 3))), r.uniform(-2, 4, n),
                       r.normal(0, 0.4, (n, 16, 3)))
    vm = viewmats(np.array([[0, 0, 0], [0, 0, 0.4]]), 0.0)
    k = np.repeat(intrinsics(W, H, HFOV)[None], 2, 0)
    a, b = Renderer(gs, "torch").render(vm, k, W, H), Renderer(gs, "cpu").render(vm, k, W, H)
    assert b.alpha.mean() > 0.5 and b.rgb.std() > 0.05  # colourful, covered views
    assert psnr(a.rgb.numpy(), b.rgb.numpy()) >= 80
    both = (a.alpha > 0.5) & (b.alpha > 0.5)
    assert torch.median((a.depth - b.depth).abs()[both]).item() <= 1e-4


@pytest.mark.parametrize("spatial_order", [True, False])
def test_block_culling_keeps_exactly_what_the_per_gaussian_test_keeps(spatial_order):
    # the compiled renderer passes over blocks of consecutive Gaussians whose bounding sphere lies
    # outside the (widened) view: conservative, so the candidates are exactly those of the
    # per-Gaussian test alone (blocks made never to cull), for views inside, at the edge and away
    from navcore.render import cpu_fast

    r = np.random.default_rng(11)
    n = 20_000
    means = r.uniform(-8, 8, (n, 3))
    if spatial_order:  # as SOG / SPZ files: neighbours next to each other, blocks small
        cell = np.floor(means / 4)  # 4 m cells, one after the other
        means = means[np.lexsort((means[:, 0], cell[:, 2], cell[:, 1], cell[:, 0]))]
    gs = GaussianScene(means, r.normal(size=(n, 4)), np.log(r.uniform(0.005, 0.4, (n, 3))), r.uniform(-6, 4, n),
                       r.normal(0, 0.3, (n, 1, 3)))
    g = cpu_fast.prepare(gs)
    everything = g["blocks"].copy()
    everything[:, 3] = 1e30  # a sphere that contains the world: never culled
    poses = np.array([[0, 0, 0], [7.5, 7.5, 2.3], [-9, 0, 0.5], [20, 20, 3.9], [0, 0, -1.2]])
    vm = viewmats(poses, 0.0)
    k = intrinsics(160, 120, 90.0)
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    args = lambda v: (np.ascontiguousarray(v[:3, :3], np.float32), np.ascontiguousarray(v[:3, 3], np.float32),  # noqa: E731
                      fx, fy, cx, cy, 160, 120, 0.01, 1e10, 1.3, 1.3)
    culled = 0
    for v in vm:
        fast = cpu_fast._cull(g["means"], g["smax"], g["opacities"], g["blocks"], *args(v), 2)
        ref = cpu_fast._cull(g["means"], g["smax"], g["opacities"], everything, *args(v), 1)  # and one worker
        assert np.array_equal(fast, ref) and np.all(np.diff(fast) > 0)
        culled += sum(cpu_fast._block_out(g["blocks"], b, *args(v)[:2], fx, fy, cx, cy, 160, 120, 0.01, 1e10,
                                          math.sqrt(1 + 1.3 ** 2), math.sqrt(1 + 1.3 ** 2))
                      for b in range(len(g["blocks"])))
    if spatial_order:
        assert culled > len(g["blocks"])  # the blocks do pass over much of the scene
    # the cull's footprint bound assumes eps2d <= SQRT_EPS2D^2: a larger one is refused, not culled wrongly
    with pytest.raises(ValueError, match="eps2d=0.5 exceeds the cull's bound"):
        cpu_fast.render_one(g, vm[0], k, 160, 120, 0, eps2d=0.5)


def test_gsplat_kernel_build_is_one_process_at_a_time(tmp_path, project_root):
    """GPU workers starting together must not build gsplat's kernels at the same time (gsplat
    deletes a build folder it finds unfinished): load_kernels imports gsplat's backend under an
    exclusive lock. A stand-in backend that takes 0.5 s to 'build' logs its start and end; three
    processes started together log three whole builds, never interleaved."""
    import os
    import subprocess
    import sys
    import textwrap

    fake = tmp_path / "fake" / "gsplat" / "cuda"
    fake.mkdir(parents=True)
    (fake.parent / "__init__.py").write_text("")
    (fake / "__init__.py").write_text("")
    log = tmp_path / "log.txt"
    (fake / "_backend.py").write_text(textwrap.dedent(f"""
        import os, time
        with open({str(log)!r}, "a") as f:
            f.write(f"start {{os.getpid()}}\\n"); f.flush()
            time.sleep(0.5)
            f.write(f"end {{os.getpid()}}\\n")
        _C = object()
    """))
    code = "from navcore.render.gsplat_backend import load_kernels; load_kernels(); load_kernels()"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "fake"), str(project_root)]),
           "TORCH_EXTENSIONS_DIR": str(tmp_path / "ext")}
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env) for _ in range(3)]
    assert all(p.wait(timeout=120) == 0 for p in procs)
    lines = log.read_text().split()
    events = list(zip(lines[0::2], lines[1::2]))
    assert len(events) == 6 and (tmp_path / "ext" / "navarena-gsplat-build.lock").exists()
    for k in range(0, 6, 2):  # each start is followed by the same process's end
        assert events[k][0] == "start" and events[k + 1] == ("end", events[k][1])


def _one_group(gs, centres):
    """offsets / index for one group of centres seeing every Gaussian."""
    return np.asarray(centres, float)[None], np.array([0, len(gs)]), np.arange(len(gs))


def test_ray_hit_depth_known_answers():
    """Per-ray hit depth: an opaque thin disc is hit on its surface along every ray (an oblique ray
    meets it at d / cos(angle), where a rasterizer reports the centre's depth); two half-transparent
    layers cross 0.5 at the second; a faint one never does."""
    from navcore.render.ray_hits import panorama_dirs, panorama_hit_depth_cpu, ray_gaussians

    disc = lambda x, a, s=0.5: ([x, 0, 0], [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0], [s, s, 0.001], a)  # noqa: E731
    parts = [disc(1.0, 0.95), disc(2.0, 0.3), disc(2.2, 0.3), disc(3.0, 0.2)]
    gs = GaussianScene.from_colors(np.array([p[0] for p in parts]), np.array([p[1] for p in parts]),
                                   np.array([p[2] for p in parts]), np.array([p[3] for p in parts]), np.full((4, 3), 0.5))
    dirs = panorama_dirs(36, -0.3, 0.3, 3)
    # from the origin: the disc at x = 1 on rays within its extent, at 1 / cos(angle to x)
    d = panorama_hit_depth_cpu(ray_gaussians(gs), *_one_group(gs, [[0, 0, 0]]), 36, 3, -0.3, 0.3, 0.0, 5.0)[0, 0]
    front = (dirs[..., 0] > np.cos(np.radians(20)))
    assert front.sum() == 12 and np.allclose(d[front], 1.0 / dirs[..., 0][front], atol=2e-3), d[front]
    assert np.isinf(d[dirs[..., 0] < 0]).all()  # nothing behind
    # from x = 1.5 facing +x: 0.3 then 0.3 -> 1 - 0.7^2 = 0.51 >= 0.5 at the second layer (x = 2.2)
    d2 = panorama_hit_depth_cpu(ray_gaussians(gs), *_one_group(gs, [[1.5, 0, 0]]), 36, 3, -0.3, 0.3, 0.0, 5.0)[0, 0]
    ahead = dirs[..., 0] > 0.99
    assert np.allclose(d2[ahead], 0.7 / dirs[..., 0][ahead], atol=2e-3), d2[ahead]
    # at a threshold of 0.6 the layers (0.51) and the faint disc behind (1 - 0.49 * 0.8 = 0.61) cross at x = 3
    d3 = panorama_hit_depth_cpu(ray_gaussians(gs), *_one_group(gs, [[1.5, 0, 0]]), 36, 3, -0.3, 0.3, 0.0, 5.0,
                                threshold=0.6)[0, 0]
    assert np.allclose(d3[ahead], 1.5 / dirs[..., 0][ahead], atol=2e-3), d3[ahead]
    with pytest.raises(ValueError, match="offsets"):
        panorama_hit_depth_cpu(ray_gaussians(gs), np.zeros((1, 1, 3)), np.array([0, 9]), np.arange(4), 36, 3, -0.3, 0.3,
                               0.0, 5.0)


def test_ray_hit_depth_numba_matches_the_torch_reference():
    """The compiled kernel (angular cull, float64), the brute-force PyTorch one (every Gaussian
    against every ray) and PyTorch's culled pair lists (the CUDA path) agree to rounding on a
    random scene of thin and round splats, groups sharing
    different subsets (an empty one too)."""
    from navcore.render.ray_hits import panorama_hit_depth_cpu, panorama_hit_depth_torch, ray_gaussians

    rng = np.random.default_rng(0)
    n = 2000
    q = rng.normal(size=(n, 4))
    gs = GaussianScene.from_colors(rng.uniform(-1, 1, (n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True),
                                   np.exp(rng.uniform(np.log(0.001), np.log(0.1), (n, 3))), rng.uniform(0.05, 1, n),
                                   np.full((n, 3), 0.5))
    g = ray_gaussians(gs)
    centres = rng.uniform(-0.5, 0.5, (4, 2, 3))
    index = np.concatenate([np.arange(n), rng.choice(n, 700, replace=False), np.arange(900)])
    offsets = np.array([0, n, n, n + 700, n + 1600])
    args = (g, centres, offsets, index, 72, 12, -0.7, 0.9, 0.0, 1.5)
    a = panorama_hit_depth_cpu(*args)
    b = panorama_hit_depth_torch(*args, device="cpu", cull=False)
    assert a.shape == (4, 2, 12, 72) and np.isinf(a[1]).all()
    assert 0.1 < np.isfinite(a).mean() < 0.9 and np.array_equal(np.isfinite(a), np.isfinite(b))
    assert np.allclose(a[np.isfinite(a)], b[np.isfinite(b)], atol=1e-9)
    # the GPU path's pair lists (the cull, in PyTorch): all groups in one batch, or one group a
    # batch in passes of 1,024 pairs, give the same
    for kw in ({}, {"chunk": 1, "max_bins": 1}):
        c = panorama_hit_depth_torch(*args, device="cpu", **kw)
        assert np.array_equal(np.isfinite(c), np.isfinite(b)) and np.allclose(c[np.isfinite(c)], b[np.isfinite(b)],
                                                                              atol=1e-9)
