"""EUVS positional mask pairing and mask-name rules, on MARS-style names (hand-derived orders)."""

from __future__ import annotations

from setdiff_bench.evaluation.euvs_compat import (
    compat_report,
    digits_key,
    mask_name_disagreements,
    positional_mispairings,
)

A = "trav_6_channel_1_img_2.jpg"  # digits 6,1,2   -> 612
B = "trav_11_channel_1_img_2.jpg"  # digits 11,1,2  -> 1112
C = "trav_6_channel_1_img_10.jpg"  # digits 6,1,10  -> 6110


def test_digits_key_concatenates_every_digit():
    assert (digits_key(A), digits_key(B), digits_key(C)) == (612, 1112, 6110)
    assert digits_key("front.jpg") == -1


def test_mars_names_are_mispaired_by_position():
    # renders by digits: A, B, C; masks as strings: trav_11..img_2 < trav_6..img_10 < trav_6..img_2 = B, C, A
    result = positional_mispairings([C, A, B])
    assert [(m.frame, m.official_mask) for m in result] == [
        (A, B.replace(".jpg", ".png")),
        (B, C.replace(".jpg", ".png")),
        (C, A.replace(".jpg", ".png")),
    ]


def test_single_digit_names_pair_correctly():
    names = ["trav_1_channel_1_img_1.jpg", "trav_1_channel_1_img_2.jpg", "trav_1_channel_2_img_1.jpg"]
    assert positional_mispairings(names) == []


def test_mask_name_rules_disagree_on_upper_case_and_multi_dot_names():
    rows = mask_name_disagreements(["a.jpg", "b.JPG", "c.d.jpg", "e.jpeg"])
    assert rows == [
        ("b.JPG", "b.JPG", "b.png", "b.png"),
        ("c.d.jpg", "c.d.png", "c.png", "c.d.png"),
        ("e.jpeg", "e.jpeg", "e.png", "e.png"),
    ]  # ".jpeg" has no ".jpg" to replace


def test_report_counts_per_scene():
    text = compat_report({"loc_06": [A, B, C], "loc_07": ["x_1.jpg"]})
    assert "scene loc_06: 3 frames, 3 positional mispairings, 0 mask-name disagreements" in text
    assert "scene loc_07: 1 frames, 0 positional mispairings, 0 mask-name disagreements" in text
    assert text.rstrip().endswith("total: 3 positional mispairings, 0 mask-name disagreements")
