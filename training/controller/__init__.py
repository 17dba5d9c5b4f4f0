"""The model controller, its CMA-ES tuner and the reference recording.

The model-based walking controller is the teacher; the shipped reference walks come from it.
"""
