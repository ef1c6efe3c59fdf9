"""Test support, not part of the API contract: every stage kind with an example setting (:mod:`.catalog`, which the
suite and ``benchmarks/robustness.py`` run through the same checks) and the extreme inputs they are held to
(:mod:`.extremes`). Like ``torch.testing``, it ships so that tests of code built on torchgrade can use it."""

__all__ = []
