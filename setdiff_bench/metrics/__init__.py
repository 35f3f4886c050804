"""Image and video quality metrics: PSNR, SSIM, LPIPS, warp error; see :mod:`.registry` for the specs.

Submodules are imported on use (LPIPS pulls in weights, warp error OpenCV's optical flow).
"""
