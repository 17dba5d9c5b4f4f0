"""Shared plumbing of the training commands.

Configs and run directories, untrusted-file readers, plots and the distributed runner.
"""
