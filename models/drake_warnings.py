"""Filters for Drake log messages the project knows to be harmless in its scenes."""
import logging


class _NoDeformableHalfSpaceWarning(logging.Filter):
    """Drops Drake's "half spaces are not supported for deformable contact" warning: these
    scenes have no deformable bodies, so it says nothing about them."""

    def filter(self, record):
        return "not currently supported for deformable contact" not in record.getMessage()


_DEFORMABLE_FILTER = _NoDeformableHalfSpaceWarning()


def silence_half_space_deformable_warning():
    logging.getLogger("drake").addFilter(_DEFORMABLE_FILTER)   # idempotent
