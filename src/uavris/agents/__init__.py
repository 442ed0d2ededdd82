"""Policies: DRL experts (Stable-Baselines3), baselines, evaluation."""
