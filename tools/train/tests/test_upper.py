"""The upper-body variant of the Fourier training images (items.fourier_items `keep`): the
person cut by the frame's lower edge, with image, mask, target series and point labels all
empty below the cut, and the crop taken from what is left."""
import torch

from volcap_train import crop as C
from volcap_train.nets import sample_features
from volcap_train.items import cut_row, fourier_items

S = 64
TOP, BOTTOM, LEFT, RIGHT = 10, 50, 26, 38  # the person: a box of rows x columns


def ndc(i):
    return -1 + 2 * i / (S - 1)


class BoxSplit:
    """One image of a box person 0.2 deep (input NDC z in [-0.1, 0.1]), labelled points
    inside (first half) and outside (second half), the layout of the dataset shards."""

    def __init__(self):
        g = torch.Generator().manual_seed(3)
        self.image = (torch.rand(1, 3, S, S, generator=g) * 255).to(torch.uint8)
        self.mask = torch.zeros(1, 1, S, S, dtype=torch.uint8)
        self.mask[0, 0, TOP : BOTTOM + 1, LEFT : RIGHT + 1] = 255
        inside = self.mask[0, 0].flatten() > 0
        counts = inside.long()
        self.ray_offsets = [torch.cat([torch.zeros(1, dtype=torch.long), counts.cumsum(0)])]
        self.ray_z = [torch.tensor([[-0.1, 0.1]]).expand(int(counts.sum()), 2).contiguous()]
        n = 400
        u = torch.rand(n, 3, generator=g)
        pin = torch.stack([ndc(LEFT + 1) + u[:, 0] * (ndc(RIGHT - 1) - ndc(LEFT + 1)), ndc(TOP + 1) + u[:, 1] * (ndc(BOTTOM - 1) - ndc(TOP + 1)), -0.08 + 0.16 * u[:, 2]], 1)
        pout = torch.stack([ndc(LEFT + 1) + u[:, 0] * (ndc(RIGHT - 1) - ndc(LEFT + 1)), ndc(TOP + 1) + u[:, 1] * (ndc(BOTTOM - 1) - ndc(TOP + 1)), 0.3 + 0.3 * u[:, 2]], 1)
        self.points = torch.cat([pin, pout])[None]
        self.occ = torch.cat([torch.ones(n), torch.zeros(n)])[None]
        self.files = ["box"]

    def __len__(self):
        return 1

    def rgb01(self, i):
        return self.image[i].float() / 255

    def mask01(self, i):
        return self.mask[i].float() / 255


def test_cut_row_keeps_the_top_fraction_of_the_person():
    m = BoxSplit().mask01(0)[0]
    assert cut_row(m, 0.5) == TOP + 20
    assert cut_row(m, 0.0) == TOP + 1  # at least one row stays
    assert cut_row(torch.zeros(S, S), 0.5) is None


def test_below_the_cut_image_mask_series_and_labels_are_empty():
    sp = BoxSplit()
    full = fourier_items(sp, 3, points=800)
    cut = fourier_items(sp, 3, points=800, keep=lambda i: 0.5)
    row = TOP + 20
    # The crop is the engine's rule on the cut mask: a shorter person, a tighter crop.
    m = sp.mask01(0).clone()
    m[..., row + 1 :, :] = 0
    s, tx, ty = C.crop_params(m[0])
    s_full = C.crop_params(sp.mask01(0)[0])[0]
    assert s < s_full
    # Point labels: inside points above the cut stay 1, those below become 0, outside stay 0.
    y = sp.points[0, :, 1]
    below = y > ndc(row + 0.5)
    lab, lab_full = cut["occ"][0], full["occ"][0]
    assert torch.equal(lab_full, sp.occ[0])
    assert (lab[below] == 0).all() and below[:400].any()
    assert torch.equal(lab[~below], sp.occ[0][~below])
    # The cut mask in crop space has no person below the cut row.
    cm = cut["mask"][0, 0].float() / 255
    rows = torch.nonzero(cm.amax(-1) > 0.5)[:, 0]
    y_crop_last = ndc(int(rows.max()))
    assert s * y_crop_last + ty <= ndc(row) + 2 * s / (S - 1) + 1e-6
    # Series: ray length (2 c0) where the points say inside, nothing where the cut emptied it.
    pts = cut["points"][0]
    c0 = sample_features(cut["coeff"][:1].float(), pts[None, :, :2])[0][:, 0]
    far_above = (y < ndc(row - 2)) & (torch.arange(800) < 400)
    far_below = (y > ndc(row + 3)) & (torch.arange(800) < 400)
    assert far_above.any() and far_below.any()
    assert (c0[far_above] > 0.05).all()
    assert (c0[far_below].abs() < 1e-6).all()


def test_the_cut_images_masks_are_the_segmenters_of_the_cut_image():
    from volcap_train.items import cut_images, cut_masks

    sp = BoxSplit()
    row = TOP + 20
    seen = []

    def segmenter(images):
        # What a segmentation of the cut frame gives: the person down to the cut only, and
        # a soft edge the true mask does not have.
        seen.append(images.clone())
        m = (images.abs().sum(1) > 0).float()
        out = torch.zeros_like(m)
        out[:, TOP : row + 1, LEFT : RIGHT + 1] = m[:, TOP : row + 1, LEFT : RIGHT + 1]
        out[:, TOP : row + 1, RIGHT + 1] = 0.6
        return out

    masks = cut_masks(sp, lambda i: 0.5, segmenter)
    # The segmenter saw the image as the cut frame shows it: unchanged down to the cut row,
    # zero below it.
    (img,) = seen
    assert torch.equal(img[0, :, : row + 1], sp.rgb01(0)[:, : row + 1])
    assert (img[0, :, row + 1 :] == 0).all()
    assert torch.equal(cut_images(sp, lambda i: 0.5), img)
    assert masks.dtype == torch.uint8 and masks.shape == (1, 1, S, S)
    assert masks[0, 0, TOP, RIGHT + 1] == 153 and masks[0, 0, row + 1 :].sum() == 0
    # The items take the crop and the mask channel from that mask, the targets from the truth.
    seg = fourier_items(sp, 3, points=800, keep=lambda i: 0.5, masks=masks)
    true = fourier_items(sp, 3, points=800, keep=lambda i: 0.5)
    p = C.crop_params(masks[0, 0].float() / 255)
    assert torch.equal(seg["mask"][0], (C.apply_crop(masks[0].float() / 255, p) * 255).round().to(torch.uint8))
    assert torch.equal(seg["occ"], true["occ"])
    # No person: the image goes through whole and its mask stays empty.
    empty = BoxSplit()
    empty.mask.zero_()
    assert torch.equal(cut_images(empty, lambda i: 0.5)[0], empty.rgb01(0))
