"""'CommonRoad scenarios': one row per run of ``make commonroad`` (``outputs/commonroad``), with
our collision verdict (our own check on the true shapes) beside the drivability checker's, the
MPC's discs beside both, the road and the goal (shown only; never judged in the ledgers)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class CommonRoadRow:
    """One run: the file's benchmark id, the method and its verdicts (see
    :class:`~pipeline.analysis.commonroad_check.CommonRoadVerdicts`)."""

    scenario: str
    method: str
    speed_mps: float | None
    steps: int
    obstacles: int
    collision_ours: bool
    collision_checker_discs: bool
    collision_checker_true_shapes: bool
    agreement_discs: str
    agreement_true_shapes: str
    off_road_steps: int
    goal_commonroad: bool
    goal_ours: bool
    #: the file's criterion: its goal reached, no contact on the true shapes (None: a result
    #: written before the criterion)
    success: bool | None = None
    min_clearance_true_shapes_m: float | None = None
    #: why the file's goal and our goal line disagree ("" when they agree)
    goal_disagreement: str = ""
    #: how the shapes were read: "cover (3 discs)", "circumscribed", ...
    shapes: str = ""
    #: obstacles first seen after the first step (out of range or hidden at first)
    seen_late: int | None = None
    #: our own check on the true shapes and the steps the checker's equals it (None: a
    #: result written before it)
    collision_ours_true_shapes: bool | None = None
    agreement_ours_true_shapes: str = ""
    #: steps off the road before the first contact on the true shapes (None: a result
    #: written before it)
    off_road_steps_before_contact: int | None = None
    #: steps in contact on the true shapes (ours) and by the discs (None: written before it)
    contact_steps_true_shapes: int | None = None
    contact_steps_discs: int | None = None

    @property
    def collision(self) -> bool:
        """The run's verdict: our own check on the true shapes (the disc check for a result
        written before it)."""
        return self.collision_ours if self.collision_ours_true_shapes is None \
            else self.collision_ours_true_shapes


@dataclass(frozen=True)
class CommonRoadSection:
    rows: tuple[CommonRoadRow, ...]

    @property
    def true_shapes_agree_everywhere(self) -> bool | None:
        """Whether our check on the true shapes and the checker's agreed on every step of
        every run (None when no run has our true-shape check)."""
        rows = [r for r in self.rows if r.agreement_ours_true_shapes]
        if not rows:
            return None
        return all(r.agreement_ours_true_shapes.split("/")[0]
                   == r.agreement_ours_true_shapes.split("/")[1] for r in rows)

    @property
    def disc_steps_differ(self) -> tuple[int, int]:
        """Runs whose steps in contact by the MPC's discs differ from those on the true shapes,
        of the runs that have both counts (the covers' bulge: a cover holds its rectangle)."""
        rows = [r for r in self.rows if r.contact_steps_true_shapes is not None
                and r.contact_steps_discs is not None]
        return (sum(r.contact_steps_discs != r.contact_steps_true_shapes for r in rows),
                len(rows))

    @property
    def discs_agree_everywhere(self) -> bool:
        """Whether the checker on our discs agreed with our check on every step of every
        run."""
        return all(r.agreement_discs.split("/")[0] == r.agreement_discs.split("/")[1]
                   for r in self.rows)


def commonroad_section(inputs: Any) -> CommonRoadSection | None:
    """The section of ``inputs.commonroad`` (the runs' results), or None without runs."""
    rows = []
    for result in inputs.commonroad:
        file, run, v = (result.summary[k] for k in ("file", "run", "verdicts"))
        steps = int(v["steps"])
        # named by the file (its benchmark id, when another, beside it)
        stem = Path(str(file["path"])).stem if file.get("path") else \
            (result.folder.parent.name if result.folder is not None else "")
        name = stem if str(file["benchmark_id"]) in (stem, "") \
            else f"{stem} (id {file['benchmark_id']})"
        reading = str(file.get("obstacle_disc", "circumscribed"))
        shapes = f"cover ({file.get('cover_discs')} discs)" if reading == "cover" else reading
        clearance = v.get("min_clearance_true_shapes_m")
        rows.append(CommonRoadRow(
            scenario=name, method=str(run["method"]),
            speed_mps=run.get("speed_mps"), steps=steps, obstacles=int(file["obstacles"]),
            collision_ours=bool(v["ours_collision"]),
            collision_checker_discs=bool(v["checker_same_geometry_collision"]),
            collision_checker_true_shapes=bool(v["checker_true_shapes_collision"]),
            agreement_discs=f"{v['agreement_same_geometry_steps']}/{steps}",
            agreement_true_shapes=f"{v['agreement_true_shapes_steps']}/{steps}",
            off_road_steps=int(v["off_road_steps"]),
            goal_commonroad=bool(v["goal_reached_commonroad"]),
            goal_ours=bool(run["goal_reached_ours"]),
            success=bool(v["success"]) if "success" in v else None,
            min_clearance_true_shapes_m=float(clearance) if clearance is not None else None,
            goal_disagreement=str(v.get("goal_disagreement") or v.get("goal_note") or ""),
            shapes=shapes, seen_late=run.get("obstacles_seen_late"),
            collision_ours_true_shapes=bool(v["ours_true_shapes_collision"])
            if "ours_true_shapes_collision" in v else None,
            agreement_ours_true_shapes=f"{v['agreement_ours_true_shapes_steps']}/{steps}"
            if "agreement_ours_true_shapes_steps" in v else "",
            off_road_steps_before_contact=int(v["off_road_steps_before_contact"])
            if int(v.get("off_road_steps_before_contact", -1)) >= 0 else None,
            contact_steps_true_shapes=int(v["ours_true_shapes_collision_steps"])
            if "ours_true_shapes_collision_steps" in v else None,
            contact_steps_discs=int(v["ours_collision_steps"])
            if "ours_collision_steps" in v else None))
    return CommonRoadSection(tuple(rows)) if rows else None
