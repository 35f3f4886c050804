"""Stage 3, scores → reports: leaderboards, plots, image grids, ablation tables, publishing results."""
