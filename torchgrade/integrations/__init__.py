"""torchgrade on other systems: grading a shot on a Ray cluster (:mod:`.ray`, the ``ray`` extra)."""

__all__ = []
