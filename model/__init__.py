"""The PyTorch side of glsynth (FCN58, losses, metrics, training), installed as glsynth.model.

Only this package and the commands that need it import torch: generating data never does.
"""
