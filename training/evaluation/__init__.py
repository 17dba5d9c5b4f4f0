"""Evaluation: report episodes, the evaluate and compare commands, robustness, statistics."""
