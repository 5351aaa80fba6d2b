"""Regrasp planners: wan_harada (roadmap), phoka_sudsang (fingers), tournassoud (grasp-placement table)."""
