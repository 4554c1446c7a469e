"""Training on the product's segmentation (seg_masks): the most prominent person as the engine
keeps it (preprocess.rs `keep_most_prominent`), and fourier_items taking the crop and the mask
channel from a predicted mask while the targets stay the ground truth's."""
import torch

from volcap_train import crop as C
from volcap_train.seg_masks import keep_most_prominent
from volcap_train.nets import sample_features
from volcap_train.train import fourier_items

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
