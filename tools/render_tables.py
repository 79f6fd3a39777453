"""Render the repository's results tables from its committed result sets.

    python tools/render_tables.py            # write every table that differs from its files
    python tools/render_tables.py --check    # write nothing; exit 1 if a table is stale

Every folder under ``docs/results/`` is a result set (``myoexo results collect EVAL_DIR
docs/results/NAME``); its tables (:func:`myoexo.evaluation.results.render`) go to
``tables.md`` beside its files, which the docs include. The short tables of other pages (the
model cards, ``myoexo/policies/MODEL_CARD*.md``) go between their markers (:data:`BLOCKS`;
a page that takes one gets its markers and a line there): a controller's headline tables
(:func:`myoexo.evaluation.results.headline_block`) or a deployable controller against its
goals (:func:`myoexo.evaluation.results.goals_block`). So no results table is typed by hand,
and ``--check`` (``make test``) fails where a committed one differs from what its files
give. This is repository tooling: the installed package writes none of these files.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from myoexo.evaluation.results import goals_block, headline_block, render

#: The repository root.
ROOT = Path(__file__).resolve().parents[1]
#: Where the committed result sets live, relative to the repository root.
RESULTS_DIR = Path("docs") / "results"
#: The rendered tables of a set, in its folder.
TABLES_FILE = "tables.md"


@dataclass(frozen=True)
class Block:
    """A generated results block in a file outside the result sets (a model card, the
    README): the headline tables of *controllers* from the set *result_set*, between the lines
    :attr:`start` and :attr:`end`.

    Attributes:
        path: The file, relative to the repository root.
        result_set: The set's folder name under :data:`RESULTS_DIR`.
        controllers: Controllers (or seed groups) of the set, in order.
    """

    path: str
    result_set: str
    controllers: tuple[str, ...]

    def _marker(self, edge: str) -> str:
        return f"<!-- myoexo-results:{self.result_set}:{','.join(self.controllers)}:{edge} -->"

    @property
    def start(self) -> str:
        return self._marker("start")

    @property
    def end(self) -> str:
        return self._marker("end")

    def render(self, root: Path) -> str:
        """The block's text, its markers included."""
        label = (RESULTS_DIR / self.result_set).as_posix()
        try:
            body = headline_block(root / label, self.controllers, label)
        except ValueError as exc:
            raise ValueError(f"{self.path}: {exc}") from exc
        return "\n".join([self.start, body, self.end])


@dataclass(frozen=True)
class GoalsBlock:
    """A generated table of a deployable controller against
    :class:`~myoexo.evaluation.criteria.DeployableGoals`, from a nominal and a perturbed
    result set of the same evaluation subjects, in *path* between its markers.

    Attributes:
        path: The file, relative to the repository root.
        controller: The deployable controller (a label or seed group of both sets).
        nominal: The nominal result set's folder name under :data:`RESULTS_DIR`.
        perturbed: The perturbed result set's.
        teacher: The controller whose command smoothness it must match (in both sets).
        device_baseline: The device's own tuned baseline it must beat (in either set that
            holds it).
    """

    path: str
    controller: str
    nominal: str
    perturbed: str
    teacher: str
    device_baseline: str

    @property
    def start(self) -> str:
        return f"<!-- myoexo-goals:{self.controller}:{self.nominal},{self.perturbed}:start -->"

    @property
    def end(self) -> str:
        return f"<!-- myoexo-goals:{self.controller}:{self.nominal},{self.perturbed}:end -->"

    def render(self, root: Path) -> str:
        """The block's text, its markers included."""
        labels = (
            (RESULTS_DIR / self.nominal).as_posix(),
            (RESULTS_DIR / self.perturbed).as_posix(),
        )
        body = goals_block(
            root / labels[0],
            root / labels[1],
            self.controller,
            self.teacher,
            self.device_baseline,
            labels,
        )
        return "\n".join([self.start, body, self.end])


#: The shipped students' five seeds at their default weight, as the result sets name them.
FINE = "student_fine_5seeds@0.25"
KNEE = "student_knee_5seeds@0.25"

#: The students distilled from `res_tone_5seeds` whose goals are judged on `eval_1000_tone` and
#: `eval_200_tone_perturbed`, each with the pages that show its goals table.
TONE_STUDENT_GOALS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("student_tone_5seeds@0.5", ("docs/results.md",)),
    ("student_guard_5seeds@0.25", ("docs/results.md",)),
    ("student_fine_5seeds@0", ("docs/results.md",)),
    (FINE, ("myoexo/policies/MODEL_CARD_student_fine.md", "docs/results.md")),
    (KNEE, ("myoexo/policies/MODEL_CARD_student_knee.md", "docs/results.md")),
)

#: Every generated block outside the result sets' own ``tables.md``.
BLOCKS: tuple[Block | GoalsBlock, ...] = (
    Block("myoexo/policies/MODEL_CARD.md", "eval_1000_twin3", ("sac",)),
    Block("myoexo/policies/MODEL_CARD.md", "eval_1000", ("guard:sac",)),
    Block("myoexo/policies/MODEL_CARD.md", "eval_1000_perturbed", ("guard:sac",)),
    Block("myoexo/policies/MODEL_CARD.md", "eval_500", ("sac",)),
    Block("myoexo/policies/MODEL_CARD.md", "eval_seeds_100", ("sac_5seeds",)),
    Block("myoexo/policies/MODEL_CARD_student_exo.md", "eval_1000_twin3", ("student_exo",)),
    Block("myoexo/policies/MODEL_CARD_student_exo.md", "eval_1000", ("student_exo",)),
    Block("myoexo/policies/MODEL_CARD_student_exo.md", "eval_1000_perturbed", ("student_exo",)),
    Block(
        "myoexo/policies/MODEL_CARD_student_exo.md",
        "eval_student_seeds_100",
        ("student_exo_3seeds",),
    ),
    Block(
        "myoexo/policies/MODEL_CARD_student_exo.md",
        "eval_student_seeds_100_perturbed",
        ("student_exo_3seeds",),
    ),
    Block("myoexo/policies/MODEL_CARD_sac_exo.md", "eval_100_perturbed", ("sac_exo",)),
    Block("myoexo/policies/MODEL_CARD_residual.md", "eval_1000_tone", ("res_tone_5seeds",)),
    Block(
        "myoexo/policies/MODEL_CARD_residual.md", "eval_200_tone_perturbed", ("res_tone_5seeds",)
    ),
    Block("myoexo/policies/MODEL_CARD_residual.md", "eval_1000_tone_perturbed", ("residual",)),
    Block("myoexo/policies/MODEL_CARD_student_smooth.md", "eval_1000_tone", ("student_smooth",)),
    Block(
        "myoexo/policies/MODEL_CARD_student_smooth.md",
        "eval_1000_tone_perturbed",
        ("student_smooth",),
    ),
    Block(
        "myoexo/policies/MODEL_CARD_student_residual.md",
        "eval_1000_twin3",
        ("student_residual_3seeds",),
    ),
    Block(
        "myoexo/policies/MODEL_CARD_student_residual.md",
        "eval_200_twin3_student_residual",
        ("student_residual_3seeds",),
    ),
    Block(
        "myoexo/policies/MODEL_CARD_student_residual.md",
        "eval_1000_twin3_student_perturbed",
        ("student_residual_3seeds",),
    ),
    Block(
        "myoexo/policies/MODEL_CARD_student_residual.md",
        "eval_200_twin3_student_residual_perturbed",
        ("student_residual_3seeds",),
    ),
    GoalsBlock(
        "myoexo/policies/MODEL_CARD_student_residual.md",
        "student_residual_3seeds",
        "eval_200_twin3_student_residual",
        "eval_200_twin3_student_residual_perturbed",
        teacher="residual",
        device_baseline="pid:tuned=exo",
    ),
    Block(
        "myoexo/policies/MODEL_CARD_student_smooth.md",
        "eval_1000_twin4",
        ("student_smooth_5seeds",),
    ),
    Block(
        "myoexo/policies/MODEL_CARD_student_smooth.md",
        "eval_1000_twin4_perturbed",
        ("student_smooth_5seeds",),
    ),
    *(
        GoalsBlock(
            page,
            "student_smooth_3seeds",
            "eval_200_twin4_student_smooth",
            "eval_200_twin4_student_smooth_perturbed",
            teacher="residual",
            device_baseline="pid:tuned=exo",
        )
        for page in ("myoexo/policies/MODEL_CARD_student_smooth.md", "docs/results.md")
    ),
    *(
        GoalsBlock(
            page,
            student,
            "eval_1000_tone",
            "eval_200_tone_perturbed",
            teacher="res_tone_5seeds",
            device_baseline="pid:tuned=exo",
        )
        for student, pages in TONE_STUDENT_GOALS
        for page in pages
    ),
    Block("myoexo/policies/MODEL_CARD_student_knee.md", "eval_1000_tone", (KNEE,)),
    Block("myoexo/policies/MODEL_CARD_student_knee.md", "eval_200_tone_perturbed", (KNEE,)),
    Block("myoexo/policies/MODEL_CARD_student_knee.md", "eval_1000_tone_perturbed", (KNEE,)),
    Block("myoexo/policies/MODEL_CARD_student_fine.md", "eval_1000_tone", (FINE,)),
    Block("myoexo/policies/MODEL_CARD_student_fine.md", "eval_1000_tone_perturbed", (FINE,)),
    *(
        GoalsBlock(
            "myoexo/policies/MODEL_CARD_student_exo.md",
            student,
            "eval_1000",
            "eval_1000_perturbed",
            teacher="guard:sac",
            device_baseline="pid:tuned=exo",
        )
        for student in ("student_exo", "guard:student_exo")
    ),
)


def write_tables(
    root: Path, check: bool = False, blocks: Sequence[Block | GoalsBlock] = BLOCKS
) -> list[str]:
    """Render every result set under ``root/docs/results`` and every block of *blocks*; with
    *check*, write nothing. Returns the files that differed from what they should hold.

    Raises:
        ValueError: A folder is no result set, a block's file lacks its markers, or its set
            or controller does not exist.
    """
    stale = []
    for folder in sorted(p for p in (root / RESULTS_DIR).iterdir() if p.is_dir()):
        text = render(folder, (RESULTS_DIR / folder.name).as_posix())
        path = folder / TABLES_FILE
        if not path.is_file() or path.read_text() != text:
            stale.append(path.relative_to(root).as_posix())
            if not check:
                path.write_text(text)
    for block in blocks:
        path = root / block.path
        text = path.read_text()
        if block.start not in text or block.end not in text:
            raise ValueError(f"{block.path} lacks the markers {block.start} ... {block.end}")
        head, rest = text.split(block.start, 1)
        _, tail = rest.split(block.end, 1)
        new = head + block.render(root) + tail
        if new != text:
            if block.path not in stale:
                stale.append(block.path)
            if not check:
                path.write_text(new)
    return stale


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--root", type=Path, default=ROOT, help="repository root (default: this tool's)"
    )
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if stale")
    args = parser.parse_args(argv)
    stale = write_tables(args.root, check=args.check)
    verb = "stale" if args.check else "written"
    for path in stale:
        print(f"{verb}: {path}")
    if args.check and stale:
        print("run `python tools/render_tables.py` to refresh them", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
