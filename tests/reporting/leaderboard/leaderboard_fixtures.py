"""Hand-made per-image rows for the leaderboard tests: :func:`images` (rows of given PSNR, SSIM and LPIPS
values) and :func:`table` (methods alpha and beta on groups lane+1 and lane+2, with a tie in lane+1)."""

from __future__ import annotations

import pandas as pd


def images(
    method: str,
    group: str,
    values: list[tuple[float, float, float]],
    *,
    dataset: str = "synthetic",
    run: str = "r",
    frames: list[str] | None = None,
) -> pd.DataFrame:
    """Per-target rows with given (psnr, ssim, lpips) values, frames f0, f1, ... of scene s."""
    frames = frames or [f"f{i}" for i in range(len(values))]
    return pd.DataFrame(
        [
            {
                "dataset": dataset,
                "protocol": dataset,
                "group": group,
                "split": "test",
                "scene": "s",
                "frame": frame,
                "method": method,
                "psnr": p,
                "ssim": s,
                "lpips": lp,
                "run": f"{run}/{method}",
            }
            for frame, (p, s, lp) in zip(frames, values)
        ]
    )


def table() -> pd.DataFrame:
    return pd.concat(
        [
            images("alpha", "lane+1", [(20.0, 0.50, 0.30), (22.0, 0.70, 0.10)]),  # 21.00 0.600 0.200
            images("alpha", "lane+2", [(18.0, 0.40, 0.40), (19.0, 0.46, 0.38)]),  # 18.50 0.430 0.390
            images(
                "beta", "lane+1", [(21.004, 0.61, 0.25), (20.996, 0.59, 0.15)]
            ),  # 21.00 0.600 0.200 (ties)
            images("beta", "lane+2", [(17.0, 0.45, 0.35), (17.5, 0.45, 0.36)]),  # 17.25 0.450 0.355
        ],
        ignore_index=True,
    )
