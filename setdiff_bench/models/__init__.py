"""Learned enhancers. ``setdiff`` holds the SetDiff set model and its DiFix-style baseline configuration."""
