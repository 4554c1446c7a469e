"""Training on the product's segmentation (seg_masks): the most prominent person as the engine
keeps it (preprocess.rs `keep_most_prominent`), and fourier_items taking the crop and the mask
channel from a predicted mask while the targets stay the ground truth's."""
import torch

from volcap_train import crop as C
from volcap_train.seg_masks import keep_most_prominent, paste_max, second_pass
from volcap_train.nets import sample_features
from volcap_train.items import fourier_items

from test_upper import BOTTOM, LEFT, RIGHT, TOP, BoxSplit


def test_the_largest_region_is_kept_with_its_soft_values_and_people_are_counted():
    m = torch.zeros(256, 256)
    m[20:200, 100:120] = 0.9  # 3,600 px: the person
    m[50:90, 10:50] = 0.7  # 1,600 px: a second person (>= 10 % of the largest, >= 0.2 % of the frame)
    m[240:250, 240:250] = 1.0  # 100 px: a fragment (< 0.2 % of the frame)
    m[0:3, 0:3] = 0.4  # not a person pixel (<= 0.5)
    kept, people = keep_most_prominent(m)
    assert people == 2
    assert torch.equal(kept[20:200, 100:120], m[20:200, 100:120])
    assert (kept > 0).sum().item() == 180 * 20


def test_regions_are_8_connected_and_ties_go_to_the_first_in_row_major_order():
    m = torch.zeros(64, 64)
    # Two 10x10 blocks joined only through a diagonal step: one region of 200 pixels.
    m[0:10, 0:10] = 1.0
    m[10:20, 10:20] = 1.0
    # A separate block of the same 200 pixels, later in row-major order.
    m[40:50, 40:60] = 0.8
    kept, people = keep_most_prominent(m)
    assert people == 2
    assert (kept[0:10, 0:10] == 1).all() and (kept[10:20, 10:20] == 1).all()
    assert kept[40:50, 40:60].sum() == 0
    # Nothing above 0.5: no person, nothing kept.
    kept, people = keep_most_prominent(torch.full((32, 32), 0.5))
    assert people == 0 and kept.sum() == 0


def test_a_u_shaped_person_is_one_region_when_its_arms_meet_below():
    # Rows scanned top-down meet the two arms as separate runs first; the bottom bar joins them.
    m = torch.zeros(64, 64)
    m[5:60, 10:14] = 1.0
    m[5:60, 40:44] = 1.0
    m[56:60, 10:44] = 1.0
    kept, people = keep_most_prominent(m)
    assert people == 1 and torch.equal(kept, m)


def test_predicted_masks_set_the_crop_and_the_mask_channel_but_not_the_targets():
    sp = BoxSplit()
    gt = fourier_items(sp, 3, points=800)
    # A segmentation that lost the box's lower quarter and added a soft halo on one side.
    pred = sp.mask.clone()
    cut = TOP + 3 * (BOTTOM - TOP) // 4
    pred[0, 0, cut:, :] = 0
    pred[0, 0, TOP:cut, RIGHT + 1 : RIGHT + 3] = 160
    seg = fourier_items(sp, 3, points=800, masks=pred)
    # fourier_items takes the shard's first 400 (inside) and last 400 (outside) points.
    sel = torch.cat([torch.arange(400), torch.arange(400, 800)])
    p = C.crop_params(pred[0, 0].float() / 255)
    assert p != C.crop_params(sp.mask01(0)[0])
    # The mask channel is the predicted mask through its own crop...
    assert torch.equal(seg["mask"][0], (C.apply_crop(pred[0].float() / 255, p) * 255).round().to(torch.uint8))
    # ...the labels are the ground truth's, only moved into that crop...
    assert torch.equal(seg["occ"], gt["occ"])
    assert torch.allclose(seg["points"][0], C.to_crop(sp.points[0][sel], p))
    # ...and the series still holds the whole box, the part the segmentation lost included:
    # at the box's inside points, the ray length (c0 in crop units, x s in input units) is
    # the ground-truth crop's, above and below the predicted mask's last row alike.
    inside = (torch.arange(800) < 400) & (sp.points[0][sel][:, 1].abs() < 1)
    lost = inside & (sp.points[0][sel][:, 1] > -1 + 2 * (cut + 2) / 63)
    assert lost.any()
    s_gt = C.crop_params(sp.mask01(0)[0])[0]
    c_seg = sample_features(seg["coeff"][:1].float(), seg["points"][:1, :, :2])[0][:, 0] * p[0]
    c_gt = sample_features(gt["coeff"][:1].float(), gt["points"][:1, :, :2])[0][:, 0] * s_gt
    assert (c_gt[inside] > 0.05).all()
    assert torch.allclose(c_seg[inside], c_gt[inside], atol=0.01)


class TwoImages(BoxSplit):
    """The box person twice (one image where the segmentation finds nobody)."""

    def __init__(self):
        super().__init__()
        for name in ("image", "mask", "points", "occ"):
            setattr(self, name, torch.cat([getattr(self, name)] * 2))
        self.ray_offsets, self.ray_z = self.ray_offsets * 2, self.ray_z * 2

    def __len__(self):
        return 2


def test_an_image_without_a_predicted_person_is_left_out():
    sp = TwoImages()
    pred = sp.mask.clone()
    pred[0] = 0
    out = fourier_items(sp, 3, points=800, masks=pred)
    assert out["keep"].tolist() == [1]
    assert torch.equal(out["mask"][0], fourier_items(sp, 3, points=800)["mask"][1])


def test_paste_max_takes_a_crop_mask_back_by_its_larger_value_inside_the_crop_only():
    into = torch.zeros(64, 64)
    into[30:34, :] = 0.7
    # The identity crop: the pasted mask is the elementwise maximum.
    m2 = torch.rand(64, 64, generator=torch.Generator().manual_seed(0))
    # (Within f32 rounding: a pixel's NDC and back lands a hair off its centre.)
    assert torch.allclose(paste_max(m2, (1.0, 0.0, 0.0), into), torch.maximum(into, m2), atol=1e-4)
    # A half-size crop in the upper left quadrant (input NDC x, y in [-1, 0]).
    p = (0.5, -0.5, -0.5)
    out = paste_max(torch.ones(64, 64), p, into)
    ndc = -1 + 2 * torch.arange(64) / 63
    inside = (ndc <= 0)[:, None] & (ndc <= 0)[None, :]
    assert (out[inside] == 1).all()
    assert torch.equal(out[~inside], into[~inside])
    # Nothing is lowered: a crop mask of zeros changes nothing.
    assert torch.equal(paste_max(torch.zeros(64, 64), p, into), into)
    # Round trip: the crop of the pasted mask is the crop mask where it is the larger (away
    # from the crop's border, where the input grid's resampling blends the outside in).
    blob = torch.zeros(64, 64)
    blob[20:44, 24:40] = 1.0
    back = C.apply_crop(paste_max(blob, p, torch.zeros(64, 64))[None], p)[0]
    assert (back[24:40, 28:36] > 0.99).all() and (back[:12] < 0.01).all()


def test_the_second_pass_adds_what_the_crop_shows_and_keeps_one_person(tmp_path, monkeypatch):
    import volcap_train.seg_masks as S

    # A first pass that lost the person's arm: the body alone.
    body = torch.zeros(1, 64, 64)
    body[0, 10:60, 28:36] = 0.9
    images = torch.zeros(1, 3, 64, 64)
    p = C.crop_params(body[0])

    def fake_segment(model, crops):
        # The second pass, on the crop: the body and the arm beside it, and a blob apart from
        # the person (a background object the crop shows).
        assert crops.shape == (1, 3, 64, 64)
        m = C.apply_crop(body, p)
        arm = torch.zeros(1, 64, 64)
        arm[0, 20:24, :] = 0.8
        arm = C.apply_crop(arm, p) * (C.apply_crop(arm, p) > 0.5)
        m = torch.maximum(m, arm)
        m[0, 2:6, 2:6] = 1.0
        return m

    monkeypatch.setattr(S, "segment", fake_segment)
    out = second_pass(tmp_path / "seg.onnx", images, body)
    assert out.shape == body.shape
    # Nothing of the first pass is lost, the arm's pixels are added...
    assert (out[0] >= body[0] - 1e-6).all()
    assert (out[0, 21:23, 5:20] > 0.5).all()
    # ...and the blob apart from the person, where it lands in the frame, is dropped by the
    # most prominent person rule.
    lone = torch.zeros(64, 64)
    lone[2:6, 2:6] = 1.0
    where = paste_max(lone, p, torch.zeros(64, 64)) > 0.5
    assert where.any() and not (body[0][where] > 0).any()
    assert (out[0][where] == 0).all()


def test_the_caches_name_the_segmenters_contents_not_only_its_file_name(tmp_path):
    """A retrained segmenter under the same name (seg_tune writes `seg.onnx`) never reads the
    masks or items cached from another; the same file always names the same cache."""
    import pytest

    from volcap_train.items import fourier_cache_path
    from volcap_train.seg_masks import model_tag

    a, b = tmp_path / "a" / "seg.onnx", tmp_path / "b" / "seg.onnx"
    for path, body in ((a, b"first weights"), (b, b"second weights")):
        path.parent.mkdir()
        path.write_bytes(body)
    assert model_tag(a).startswith("seg-") and model_tag(a) != model_tag(b)
    assert model_tag(a) == model_tag(tmp_path / "a" / "seg.onnx")
    assert fourier_cache_path(tmp_path, "train", 15, a, 2) != fourier_cache_path(tmp_path, "train", 15, b, 2)
    with pytest.raises(FileNotFoundError, match="missing.onnx: no such segmentation model"):
        model_tag(tmp_path / "missing.onnx")
