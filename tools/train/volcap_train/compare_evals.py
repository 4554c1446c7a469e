"""Paired comparison of two models through the engine: `volcap eval` reports of the same
images, image by image, with standard errors.

  python -m volcap_train.compare_evals --a A1 [A2 ...] --b B1 [B2 ...] [--model-a M] [--model-b M] [--by-subject]

Each Ai / Bi is a `volcap eval --out` folder (its eval.json, or eval.json.xz as `slim_docs
--pack-json` leaves the committed ones) or the file itself; Ai and Bi must
be runs on the same images (same --subjects, --poses, --views and --seed), so their images pair
by (subject, pose, yaw); the pairs of all the reports pool. Per metric it prints both means,
the mean of the per-image differences A - B with its standard error, how many images A
wins, and the median difference. Means of 42 images move by 0.1-0.2 cm between checkpoints of one recipe (docs/eval/
hands.md section 23): a difference within two standard errors of 0 is not a finding.

The per-image differences are heavy-tailed: a few images flip between two readings from one
checkpoint to the next (one held-out subject's side views, whose hidden leg lands at one depth
or another: 1 cm against 3-5 cm P2S, hands.md section 42) and move the mean by several
hundredths on their own. The median, and `--by-subject` (the mean differences per held-out
subject), show whether a difference is everywhere or one subject's.
"""
from __future__ import annotations

import argparse
import json
import lzma
import math
import statistics
from pathlib import Path

# (key in an image row, label, whether larger is better); part_cm[3] is the hands'
# completeness (volcap eval's part order: head, torso, arms, hands, legs, feet).
METRICS = [
    ("chamfer_cm", "Chamfer cm", False),
    ("p2s_cm", "P2S cm", False),
    ("iou", "IoU", True),
    ("hands_cm", "hands cm", False),
    # part_shown[3] in %: the share of the hands' true surface within 2 cm of the
    # reconstruction (reports made before 2026-12-01 have none: left out for them).
    ("hands_shown", "hands shown %", True),
    # 1 on a facing error (`volcap eval`'s `facing_error`: the reconstruction nearer the truth
    # turned around in depth), else 0: its mean is the share of such images. Reports made
    # before 2026-11-29 have no such field: the metric is left out for them.
    ("facing", "facing errors (share)", False),
]


def load_rows(path: Path, model: str | None) -> dict:
    """The ok images of one report as {(subject, pose, yaw): row}; `model` picks one of several
    models in the report (needed when it holds more than one)."""
    f = path
    if path.is_dir():
        f = next((path / n for n in ("eval.json", "eval.json.xz") if (path / n).exists()), path / "eval.json")
    if not f.exists():
        raise SystemExit(f"{path}: no eval.json (a `volcap eval --out` folder or the file)")
    data = lzma.decompress(f.read_bytes()) if f.suffix == ".xz" else f.read_bytes()
    rows = json.loads(data)["images"]
    models = sorted({r["model"] for r in rows})
    if model is None:
        if len(models) != 1:
            raise SystemExit(f"{f}: {len(models)} models ({', '.join(models)}): name one with --model-a/--model-b")
        model = models[0]
    elif model not in models:
        raise SystemExit(f"{f}: no model {model!r} (it has {', '.join(models)})")
    out = {}
    for r in rows:
        if r["model"] != model or r["status"] != "ok":
            continue
        r = dict(r)
        parts = r.get("part_cm") or []
        r["hands_cm"] = parts[3] if len(parts) > 3 else float("nan")
        shown = r.get("part_shown")
        if shown is not None:
            r["hands_shown"] = shown[3] * 100.0 if len(shown) > 3 and shown[3] is not None else float("nan")
        if "facing_error" in r:
            r["facing"] = float(r["facing_error"])
        for key, _, _ in METRICS:
            # `volcap eval` writes a value it could not measure (NaN: a part the frame does
            # not show, so no true sample of it) as null: such an image drops out of that
            # metric's pairs only. (Reports made before 2026-11-29 also hold nulls from a
            # metric bug, degenerate mesh triangles: docs/eval/hands.md section 27.)
            # (The facing and hands-shown columns are absent from reports made before them:
            # left out, not NaN.)
            if key not in ("facing", "hands_shown") and r.get(key) is None:
                r[key] = float("nan")
        out[(r["subject"], r["pose"], r["yaw_deg"])] = r
    return out


def paired(a_rows: list[dict], b_rows: list[dict]) -> list[tuple[dict, dict]]:
    """The image pairs of report pairs (a_rows[i], b_rows[i]), pooled."""
    if len(a_rows) != len(b_rows):
        raise SystemExit(f"--a has {len(a_rows)} reports and --b {len(b_rows)}: pair them one to one")
    pairs = []
    for i, (a, b) in enumerate(zip(a_rows, b_rows)):
        common = sorted(set(a) & set(b))
        if not common:
            raise SystemExit(f"report pair {i + 1}: no image in common (not the same images?)")
        pairs += [(a[k], b[k]) for k in common]
    return pairs


def compare(pairs: list[tuple[dict, dict]]) -> list[dict]:
    """Per metric: both means, the mean per-image difference A - B, its standard error and A's
    wins, over the pairs where both values are finite."""
    out = []
    for key, label, higher in METRICS:
        nan = float("nan")
        d = [(a.get(key, nan), b.get(key, nan)) for a, b in pairs]
        d = [(x, y) for x, y in d if math.isfinite(x) and math.isfinite(y)]
        if not d:
            continue
        n = len(d)
        diff = [x - y for x, y in d]
        mean = sum(diff) / n
        se = math.sqrt(sum((x - mean) ** 2 for x in diff) / (n - 1) / n) if n > 1 else float("nan")
        wins = sum((x > y) if higher else (x < y) for x, y in d)
        out.append(
            {
                "metric": label,
                "images": n,
                "a": sum(x for x, _ in d) / n,
                "b": sum(y for _, y in d) / n,
                "diff": mean,
                "se": se,
                "a_wins": wins,
                "median": statistics.median(diff),
            }
        )
    return out


# --by-subject: the metrics of the per-subject table (key, label).
SUBJECT_METRICS = [("chamfer_cm", "Chamfer cm"), ("p2s_cm", "P2S cm"), ("hands_cm", "hands cm")]


def by_subject(pairs: list[tuple[dict, dict]]) -> list[dict]:
    """Per held-out subject (sorted): its images and, per metric of SUBJECT_METRICS, the mean
    difference A - B and its standard error over that subject's pairs with both values finite
    (NaN where none; the error NaN under two)."""
    subjects = sorted({a["subject"] for a, _ in pairs})
    out = []
    for s in subjects:
        sp = [(a, b) for a, b in pairs if a["subject"] == s]
        row = {"subject": s, "images": len(sp)}
        for key, label in SUBJECT_METRICS:
            nan = float("nan")
            d = [a.get(key, nan) - b.get(key, nan) for a, b in sp]
            d = [x for x in d if math.isfinite(x)]
            n = len(d)
            mean = sum(d) / n if n else nan
            se = math.sqrt(sum((x - mean) ** 2 for x in d) / (n - 1) / n) if n > 1 else nan
            row[label] = (mean, se)
        out.append(row)
    return out


def subject_table(rows: list[dict]) -> str:
    labels = [label for _, label in SUBJECT_METRICS]
    s = "| subject | images | " + " | ".join(f"{l}: A - B" for l in labels) + " |\n"
    s += "|---|---|" + "---|" * len(labels) + "\n"
    for r in rows:
        s += f"| {r['subject']} | {r['images']} | " + " | ".join(f"{r[l][0]:+.3f} ± {r[l][1]:.3f}" for l in labels) + " |\n"
    return s


def table(res: list[dict]) -> str:
    s = "| metric | images | A | B | A - B (per image) | A better on | median A - B |\n|---|---|---|---|---|---|---|\n"
    for r in res:
        s += (
            f"| {r['metric']} | {r['images']} | {r['a']:.3f} | {r['b']:.3f} | "
            f"{r['diff']:+.3f} ± {r['se']:.3f} | {r['a_wins']} | {r['median']:+.3f} |\n"
        )
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--a", type=Path, nargs="+", required=True)
    ap.add_argument("--b", type=Path, nargs="+", required=True)
    ap.add_argument("--model-a", default=None)
    ap.add_argument("--model-b", default=None)
    ap.add_argument("--by-subject", action="store_true", help="also the mean differences per held-out subject (Chamfer, P2S, hands)")
    args = ap.parse_args(argv)
    a = [load_rows(p, args.model_a) for p in args.a]
    b = [load_rows(p, args.model_b) for p in args.b]
    pairs = paired(a, b)
    print(table(compare(pairs)), end="")
    if args.by_subject:
        print()
        print(subject_table(by_subject(pairs)), end="")


if __name__ == "__main__":
    main()
