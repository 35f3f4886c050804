"""Rasterisation backends: ``torch_ref`` (pure PyTorch, any device) and ``gsplat`` (CUDA)."""
