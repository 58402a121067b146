"""Task kinds of eq. (5): ``position`` (r = 3, the paper's) and ``pose`` (r = 6, docs/model.md "Any robot")."""

from .pose import orientation_error, quat_to_matrix, rotation_to_quat

__all__ = ["orientation_error", "quat_to_matrix", "rotation_to_quat"]
