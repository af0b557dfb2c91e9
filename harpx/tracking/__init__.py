"""Tracking a finite-element body through harmonic-phase images (paper §3)."""
