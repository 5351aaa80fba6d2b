"""Regrasp workbench: grasp, placement and regrasp planning (Wan & Harada; Phoka & Sudsang; Tournassoud et al.)."""

__version__ = "0.1.0"
