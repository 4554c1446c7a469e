"""Online hard example mining (MonoPort, METHOD.md), in the log domain.

Stored values, as the paper defines them:

* per image ("item"):  ``1 / P_im = exp(-IoU / alpha_i + beta_i)``, alpha_i = 0.15, beta_i = 10;
* per point:           ``1 / P_pt = 1 / (exp(-L_BCE / alpha_p) + beta_p)``, alpha_p = 0.7, beta_p = 0.

The stored values are un-normalized sampling weights: after normalization they are the
probabilities with which items and points are drawn. With beta_p = 0 the point weight is
``exp(L / 0.7)``, which overflows float32 for a confidently wrong point (L >= ~62). We
therefore never form the weights themselves: we store their logarithms,

* ``log_w_im = -IoU / alpha_i + beta_i``
* ``log_w_pt = -logaddexp(-L / alpha_p, log(beta_p))``   (= L / alpha_p when beta_p = 0)

and normalize with log-sum-exp, so probabilities are finite and sum to 1 for any finite loss.
"""

from __future__ import annotations

import math

import torch

ALPHA_I = 0.15
BETA_I = 10.0
ALPHA_P = 0.7
BETA_P = 0.0

MODES = ("none", "P", "P+I")


def log_item_weight(iou: torch.Tensor, alpha: float = ALPHA_I, beta: float = BETA_I) -> torch.Tensor:
    """log(1 / P_im) for IoU values in [0, 1] (clamped; NaN refused)."""
    if torch.isnan(iou).any():
        raise ValueError("item IoU contains NaN")
    return -iou.clamp(0.0, 1.0) / alpha + beta


def log_point_weight(bce: torch.Tensor, alpha: float = ALPHA_P, beta: float = BETA_P) -> torch.Tensor:
    """log(1 / P_pt) = -log(exp(-L / alpha) + beta), computed without forming exp(L / alpha).

    BCE must be >= 0 and not NaN; +inf is clamped to the largest finite float32 so that the
    result stays finite (such a point simply gets all the probability mass of its item)."""
    if torch.isnan(bce).any():
        raise ValueError("point BCE contains NaN")
    if (bce < 0).any():
        raise ValueError("point BCE must be >= 0")
    l = bce.to(torch.float64).clamp(max=torch.finfo(torch.float32).max)
    a = -l / alpha
    if beta > 0.0:
        out = -torch.logaddexp(a, torch.full_like(a, math.log(beta)))
    else:
        out = -a
    return out


def normalize(log_w: torch.Tensor) -> torch.Tensor:
    """Probabilities from log weights (log-sum-exp), float64, finite, summing to 1."""
    if log_w.numel() == 0:
        raise ValueError("no weights to normalize")
    lw = log_w.to(torch.float64)
    if not torch.isfinite(lw).all():
        raise ValueError("log weights must be finite")
    return torch.exp(lw - torch.logsumexp(lw, dim=-1, keepdim=True))


class OhemState:
    """Per-item and per-point stored log weights, updated from the latest visit."""

    def __init__(self, items: int, points: int, mode: str):
        if mode not in MODES:
            raise ValueError(f"OHEM mode {mode!r} is not one of {MODES}")
        self.mode = mode
        # Initial: every item and point equally likely (IoU 0, BCE ln 2 for an untrained net).
        self.log_item = log_item_weight(torch.zeros(items, dtype=torch.float64))
        self.log_point = log_point_weight(torch.full((items, points), math.log(2.0), dtype=torch.float64))

    def sample_items(self, n: int, gen: torch.Generator) -> torch.Tensor:
        if self.mode == "P+I":
            p = normalize(self.log_item)
        else:
            p = torch.full((self.log_item.numel(),), 1.0 / self.log_item.numel(), dtype=torch.float64)
        return torch.multinomial(p, n, replacement=True, generator=gen)

    def sample_points(self, items: torch.Tensor, n: int, gen: torch.Generator) -> torch.Tensor:
        """[len(items), n] point indices per item."""
        if self.mode == "none":
            npts = self.log_point.shape[1]
            return torch.randint(0, npts, (len(items), n), generator=gen)
        p = normalize(self.log_point[items])
        return torch.multinomial(p, n, replacement=True, generator=gen)

    def update(self, items: torch.Tensor, points: torch.Tensor, bce: torch.Tensor, pred: torch.Tensor, label: torch.Tensor):
        """Store the latest losses of the visited points and each visited item's IoU."""
        with torch.no_grad():
            self.log_point[items[:, None], points] = log_point_weight(bce.detach().to(torch.float64))
            inside_p = pred.detach() > 0.5
            inside_l = label > 0.5
            inter = (inside_p & inside_l).sum(dim=1).to(torch.float64)
            union = (inside_p | inside_l).sum(dim=1).to(torch.float64)
            iou = torch.where(union > 0, inter / union.clamp(min=1), torch.ones_like(union))
            self.log_item[items] = log_item_weight(iou)

    def state_dict(self):
        return {"mode": self.mode, "log_item": self.log_item, "log_point": self.log_point}

    def load_state_dict(self, d):
        self.mode = d["mode"]
        self.log_item = d["log_item"]
        self.log_point = d["log_point"]
