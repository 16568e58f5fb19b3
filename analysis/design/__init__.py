"""The design stage: the application's requirements at the wheel and the machine shaft, and
e-powertrain concepts searched by NSGA-II, each simulated by the simulate stage's kernel in
batches (docs/design.md).

Public: `DesignOptions`, `DesignResult`, `design_concepts`, `write_design`, `design_chapter`; the
pipeline's stage is `analysis.design.stage.design_stage`.
"""

from __future__ import annotations

from .options import DesignOptions
from .result import DesignResult, write_design

__all__ = ["DesignOptions", "DesignResult", "design_chapter", "design_concepts", "write_design"]


def design_concepts(*args, **kwargs) -> DesignResult:
    from .synthesis import design_concepts as run

    return run(*args, **kwargs)


def design_chapter(summary: dict, out_dir):
    from .chapter import design_chapter as chapter

    return chapter(summary, out_dir)
