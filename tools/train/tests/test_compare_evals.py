"""compare_evals: paired per-image differences of two `volcap eval` reports."""
import json
import math
import statistics

import pytest

from volcap_train import compare_evals as ce


def report(tmp_path, name, rows, facing=None, shown=None):
    d = tmp_path / name
    d.mkdir()
    images = []
    for i, (subject, pose, yaw, model, c, p, iou, hands) in enumerate(rows):
        images.append(
            {
                "subject": subject, "pose": pose, "yaw_deg": yaw, "model": model, "status": "ok",
                "chamfer_cm": c, "p2s_cm": p, "iou": iou, "part_cm": [1, 1, 1, hands, 1, 1],
            }
        )
        if facing is not None:
            images[-1]["facing_error"] = facing[i]
        if shown is not None:
            images[-1]["part_shown"] = [1, 1, 1, shown[i], 1, 1]
    (d / "eval.json").write_text(json.dumps({"images": images, "models": []}))
    return d


def test_pairs_by_image_and_gives_the_mean_difference_and_its_standard_error(tmp_path):
    # B lists its images in another order and holds one A lacks: pairing is by image.
    a = report(tmp_path, "a", [("s1", 0, 0.0, "m", 2.0, 1.0, 0.7, 10.0), ("s1", 0, 120.0, "m", 3.0, 2.0, 0.6, 12.0),
                               ("s2", 1, 0.0, "m", 1.0, 0.5, 0.8, 8.0)])
    b = report(tmp_path, "b", [("s2", 1, 0.0, "m", 1.5, 0.5, 0.7, 9.0), ("s9", 0, 0.0, "m", 9.0, 9.0, 0.1, 30.0),
                               ("s1", 0, 120.0, "m", 2.0, 2.5, 0.65, 12.0), ("s1", 0, 0.0, "m", 2.5, 1.5, 0.6, 11.0)])
    res = {r["metric"]: r for r in ce.compare(ce.paired([ce.load_rows(a, None)], [ce.load_rows(b, None)]))}
    d = [2.0 - 2.5, 3.0 - 2.0, 1.0 - 1.5]
    c = res["Chamfer cm"]
    assert c["images"] == 3
    assert math.isclose(c["diff"], statistics.fmean(d))
    assert math.isclose(c["se"], statistics.stdev(d) / math.sqrt(3))
    assert math.isclose(c["a"], 2.0) and math.isclose(c["b"], 2.0)
    assert c["a_wins"] == 2  # lower is better
    assert res["IoU"]["a_wins"] == 2  # higher is better: 0.7 > 0.6, 0.8 > 0.7
    assert math.isclose(res["hands cm"]["diff"], statistics.fmean([-1.0, 0.0, -1.0]))
    assert "| Chamfer cm | 3 |" in ce.table(list(res.values()))
    assert math.isclose(c["median"], statistics.median(d))


def test_the_median_and_the_subjects_show_a_difference_that_is_one_images(tmp_path):
    # Five images alike and one that flips: the mean moves, the median does not, and the
    # per-subject table puts the whole difference on the flipping image's subject.
    rows_b = [(f"s{i % 3}", 0, 120.0 * (i // 3), "m", 1.0, 1.0, 0.7, 10.0) for i in range(6)]
    rows_a = [(s, p, y, m, c, 4.0 if (s, y) == ("s2", 120.0) else pp, iou, h) for s, p, y, m, c, pp, iou, h in rows_b]
    a, b = report(tmp_path, "a", rows_a), report(tmp_path, "b", rows_b)
    pairs = ce.paired([ce.load_rows(a, None)], [ce.load_rows(b, None)])
    p2s = {r["metric"]: r for r in ce.compare(pairs)}["P2S cm"]
    assert math.isclose(p2s["diff"], 0.5) and p2s["median"] == 0.0
    subj = {r["subject"]: r for r in ce.by_subject(pairs)}
    assert sorted(subj) == ["s0", "s1", "s2"] and all(r["images"] == 2 for r in subj.values())
    assert subj["s0"]["P2S cm"] == (0.0, 0.0) and subj["s1"]["P2S cm"] == (0.0, 0.0)
    assert math.isclose(subj["s2"]["P2S cm"][0], 1.5) and math.isclose(subj["s2"]["P2S cm"][1], 1.5)
    t = ce.subject_table(ce.by_subject(pairs))
    assert "| s2 | 2 | +0.000 ± 0.000 | +1.500 ± 1.500 |" in t


def test_the_hands_shown_compare_in_percent_higher_better_and_only_where_both_reports_have_them(tmp_path):
    rows = [("s1", 0, 0.0, "m", 2.0, 1.0, 0.7, 10.0), ("s1", 0, 120.0, "m", 2.0, 1.0, 0.7, 10.0)]
    a = report(tmp_path, "a", rows, shown=[0.6, None])  # the second image shows no hand (null)
    b = report(tmp_path, "b", rows, shown=[0.4, 0.5])
    old = report(tmp_path, "old", rows)  # made before the column
    res = {r["metric"]: r for r in ce.compare(ce.paired([ce.load_rows(a, None)], [ce.load_rows(b, None)]))}
    h = res["hands shown %"]
    assert h["images"] == 1 and math.isclose(h["diff"], 20.0) and h["a_wins"] == 1
    res_old = {r["metric"] for r in ce.compare(ce.paired([ce.load_rows(old, None)], [ce.load_rows(b, None)]))}
    assert "hands shown %" not in res_old and "hands cm" in res_old


def test_report_pairs_pool_and_mismatches_are_refused(tmp_path):
    a1 = report(tmp_path, "a1", [("s1", 0, 0.0, "m", 2.0, 1.0, 0.7, 10.0)])
    a2 = report(tmp_path, "a2", [("s1", 0, 0.0, "m", 4.0, 1.0, 0.7, 10.0)])
    b1 = report(tmp_path, "b1", [("s1", 0, 0.0, "m", 1.0, 1.0, 0.7, 10.0)])
    b2 = report(tmp_path, "b2", [("s2", 0, 0.0, "m", 1.0, 1.0, 0.7, 10.0)])
    rows = lambda ps: [ce.load_rows(p, None) for p in ps]
    # The same image key in two report pairs is two images (another seed, another pose).
    pooled = ce.compare(ce.paired(rows([a1, a2]), rows([b1, b1])))
    assert pooled[0]["images"] == 2 and math.isclose(pooled[0]["diff"], 2.0)
    with pytest.raises(SystemExit, match="no image in common"):
        ce.paired(rows([a1]), rows([b2]))
    with pytest.raises(SystemExit, match="pair them one to one"):
        ce.paired(rows([a1, a2]), rows([b1]))


def test_a_report_of_several_models_needs_one_named(tmp_path):
    r = report(tmp_path, "r", [("s1", 0, 0.0, "m1", 2.0, 1.0, 0.7, 10.0), ("s1", 0, 0.0, "m2", 1.0, 1.0, 0.7, 10.0)])
    with pytest.raises(SystemExit, match="2 models"):
        ce.load_rows(r, None)
    assert ce.load_rows(r, "m2")[("s1", 0, 0.0)]["chamfer_cm"] == 1.0
    with pytest.raises(SystemExit, match="no model 'm3'"):
        ce.load_rows(r, "m3")
    with pytest.raises(SystemExit, match="no eval.json"):
        ce.load_rows(tmp_path / "missing", None)


def test_a_value_eval_could_not_measure_drops_that_image_from_that_metric_only(tmp_path):
    # `volcap eval` writes NaN as null (a part with no true sample on one image)
    a = report(tmp_path, "a", [("s1", 0, 0.0, "m", 2.0, 1.0, 0.7, None), ("s2", 0, 0.0, "m", 3.0, 2.0, 0.6, 12.0)])
    b = report(tmp_path, "b", [("s1", 0, 0.0, "m", 2.5, 1.5, 0.6, 11.0), ("s2", 0, 0.0, "m", 2.0, 2.5, 0.65, 10.0)])
    res = {r["metric"]: r for r in ce.compare(ce.paired([ce.load_rows(a, None)], [ce.load_rows(b, None)]))}
    assert res["hands cm"]["images"] == 1 and math.isclose(res["hands cm"]["diff"], 2.0)
    assert res["Chamfer cm"]["images"] == 2


def test_facing_errors_compare_as_a_share_and_older_reports_leave_them_out(tmp_path):
    rows = [("s1", 0, 0.0, "m", 2.0, 1.0, 0.7, 10.0), ("s2", 0, 0.0, "m", 3.0, 2.0, 0.6, 12.0),
            ("s3", 0, 0.0, "m", 3.0, 2.0, 0.6, 12.0)]
    a = report(tmp_path, "a", rows, facing=[False, False, True])
    b = report(tmp_path, "b", rows, facing=[True, True, False])
    old = report(tmp_path, "old", rows)
    res = {r["metric"]: r for r in ce.compare(ce.paired([ce.load_rows(a, None)], [ce.load_rows(b, None)]))}
    f = res["facing errors (share)"]
    assert f["images"] == 3 and math.isclose(f["a"], 1 / 3) and math.isclose(f["b"], 2 / 3)
    assert f["a_wins"] == 2  # fewer is better: right where B is reversed
    res = {r["metric"] for r in ce.compare(ce.paired([ce.load_rows(a, None)], [ce.load_rows(old, None)]))}
    assert "facing errors (share)" not in res and "Chamfer cm" in res
