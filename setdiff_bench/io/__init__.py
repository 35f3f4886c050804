"""File I/O shared by every stage: atomic writes, images (PNG/JPEG/EXR via OpenImageIO), safe paths."""
