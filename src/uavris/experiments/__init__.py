"""Pipelines, reports and plots built on the environment and the agents."""
