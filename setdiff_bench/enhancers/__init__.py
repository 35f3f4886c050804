"""Enhancers: methods that turn a packet's target renders into improved images (see ``base``)."""
