"""train.mirror_some (`train fourier --flip`): a mirrored image's maps, mirrored back, line up
with the image's own targets: mirroring is exact in crop NDC for the 256 px input and the
128 px maps alike, and only the chosen images change."""
import torch

from volcap_train import fourier as FO
from volcap_train.train import fourier_query, mirror_some

K = 15


def test_mirrored_maps_answer_at_mirrored_points():
    g = torch.Generator().manual_seed(1)
    maps = torch.randn(2, FO.channels(K), 128, 128, generator=g)
    pts = torch.rand(2, 500, 3, generator=g) * 2 - 1
    pts[..., 2] *= 0.5
    flips = torch.tensor([True, True])
    mirrored = pts * torch.tensor([-1.0, 1.0, 1.0])
    a = fourier_query(mirror_some(maps, flips), pts, K)
    b = fourier_query(maps, mirrored, K)
    assert torch.allclose(a, b, atol=1e-4)


def test_input_and_map_grids_mirror_about_the_same_axis():
    # An input image with one bright column, and the 128 px map sampled from it (bilinear,
    # align_corners=True, the encoder's grid): mirroring then resampling equals resampling
    # then mirroring.
    img = torch.zeros(1, 1, 256, 256)
    img[..., 37] = 1.0
    down = lambda t: torch.nn.functional.interpolate(t, size=(128, 128), mode="bilinear", align_corners=True)
    flips = torch.tensor([True])
    a, b = down(mirror_some(img, flips)), mirror_some(down(img), flips)
    assert a.abs().sum() > 0.1  # the column reaches the map
    assert torch.allclose(a, b, atol=1e-4)  # f32 rounding of the sample positions


def test_only_the_chosen_images_change_and_twice_is_nothing():
    t = torch.randn(3, 4, 8, 8)
    flips = torch.tensor([True, False, True])
    m = mirror_some(t, flips)
    assert torch.equal(m[1], t[1])
    assert torch.equal(m[0], t[0].flip(-1)) and not torch.equal(m[0], t[0])
    assert torch.equal(mirror_some(m, flips), t)
    assert mirror_some(t, None) is t


def _items(seed: int, size: int, points: int) -> dict:
    """Two random point_iou items: images and masks `size` px a side, `points` labelled points."""
    g = torch.Generator().manual_seed(seed)
    return {
        "rgb": torch.randint(0, 255, (2, 3, size, size), dtype=torch.uint8, generator=g),
        "mask": torch.randint(0, 255, (2, 1, size, size), dtype=torch.uint8, generator=g),
        "points": torch.rand(2, points, 3, generator=g) * 2 - 1,
        "occ": (torch.rand(2, points, generator=g) > 0.5).float(),
    }


def test_point_iou_mirrored_items_are_the_same_people_seen_mirrored():
    # point_iou --mirrored: a net's answer for a mirrored item at its mirrored point is its
    # answer for the mirrored input's maps mirrored back at the original point: one mirror.
    from volcap_train.nets import FourierNet
    from volcap_train.point_iou import mirrored
    from volcap_train.train import predict_points

    d = _items(2, 256, 300)
    m = mirrored(d)
    assert torch.equal(m["occ"], d["occ"]) and torch.equal(mirrored(m)["points"], d["points"])
    torch.manual_seed(0)
    net = FourierNet(K, 4).eval()
    got = predict_points(net, m["rgb"], m["mask"], m["points"])
    from volcap_train.nets import encoder_input

    with torch.no_grad():
        maps = net(encoder_input(m["rgb"].float() / 255, m["mask"].float() / 255))
    want = fourier_query(mirror_some(maps, torch.tensor([True, True])), d["points"], K)
    assert torch.allclose(got, want, atol=1e-4)


def test_turned_items_are_mirrored_inputs_with_the_labels_half_turned():
    # point_iou's `turned`: the mirrored inputs, the labels' x and depth negated (a half
    # turn about the vertical axis), the labels themselves and the input items untouched.
    from volcap_train.point_iou import mirrored, turned

    d = _items(3, 8, 50)
    before = d["points"].clone()
    t, m = turned(d), mirrored(d)
    assert torch.equal(d["points"], before)
    assert torch.equal(t["rgb"], m["rgb"]) and torch.equal(t["mask"], m["mask"])
    assert torch.equal(t["points"], before * torch.tensor([-1.0, 1.0, -1.0]))
    assert torch.equal(t["occ"], d["occ"])


def test_depth_reversed_items_negate_only_the_labels_depth():
    from volcap_train.point_iou import depth_reversed

    d = _items(2, 8, 40)
    before = d["points"].clone()
    r = depth_reversed(d)
    assert torch.equal(d["points"], before)
    assert torch.equal(r["points"], before * torch.tensor([1.0, 1.0, -1.0]))
    assert torch.equal(r["rgb"], d["rgb"]) and torch.equal(r["occ"], d["occ"])


def test_facing_split_counts_the_images_closer_to_the_reversed_truth():
    from volcap_train.point_iou import facing_split

    plain = torch.tensor([0.8, 0.3, 0.7, 0.4])
    rev = torch.tensor([0.4, 0.6, 0.2, 0.5])
    r = facing_split(plain, rev)
    assert (r["errors"], r["images"]) == (2, 4)
    assert abs(r["iou_errors"] - 0.35) < 1e-6 and abs(r["iou_rest"] - 0.75) < 1e-6
    none = facing_split(plain, plain * 0.5)
    assert none["errors"] == 0 and none["iou_errors"] != none["iou_errors"]  # nan: no errors


def test_a_net_that_reverses_depth_is_all_facing_errors():
    # Predictions that are the labels with depth reversed, through the real scoring path:
    # occupancy at a point = the truth at the point with its depth negated.
    from volcap_train import fourier as FO
    from volcap_train.point_iou import depth_reversed, facing_split

    g = torch.Generator().manual_seed(3)
    pts = torch.rand(3, 400, 3, generator=g) * 2 - 1
    inside = lambda p: ((p[..., 0] ** 2 + (p[..., 2] - 0.3) ** 2) < 0.25).float()  # off-centre in depth
    lab = inside(pts) > 0.5
    wrong = lambda p: inside(p * torch.tensor([1.0, 1.0, -1.0]))
    plain = FO.level_iou(wrong(pts), lab, 0.5)
    rev = FO.level_iou(wrong(depth_reversed({"points": pts})["points"]), lab, 0.5)
    r = facing_split(plain, rev)
    assert r["errors"] == 3 and r["iou_errors"] < 0.6
