"""Scaffold-GS: anchor-based neural Gaussians."""
