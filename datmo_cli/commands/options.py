"""Click options shared by several commands."""

from __future__ import annotations

from ..progress import quiet_option

__all__ = ["quiet_option"]
