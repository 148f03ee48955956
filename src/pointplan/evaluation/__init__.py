"""Evaluation: independent path checks, per-problem records and summary metrics."""

from .evaluate import (
    EpisodeRecord,
    EvalReport,
    PathCheck,
    check_path,
    densify,
    evaluate,
    format_table,
    path_length,
)

__all__ = [
    "EpisodeRecord",
    "EvalReport",
    "PathCheck",
    "check_path",
    "densify",
    "evaluate",
    "format_table",
    "path_length",
]
