"""The multiverse's result (``make multiverse``): its design, every specification's ledger rows,
the robustness of each claim, the per-dimension effects and the space it was run on."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import pandas as pd

from pipeline.store.files import csv_text, write_csv_atomic, write_json_atomic
from pipeline.store.manifest import check, untrust, write_manifest
from pipeline.studies.results.base import ResultError, figure_files, read_json, written

DESIGN = "design.csv"
SPECIFICATIONS = "specifications.csv"
ROBUSTNESS = "robustness.csv"
DIMENSIONS = "dimensions.csv"
SPACE = "space.json"
#: The folder's files, in the manifest's order.
FILES = (DESIGN, SPECIFICATIONS, ROBUSTNESS, DIMENSIONS, SPACE)
#: The specification curves the command draws, one per claim: ``figures/<stem><claim>``.
FIGURES = "figures"
CURVE_STEM = "specification_curve_"


@dataclass(frozen=True)
class MultiverseInfo:
    """``space.json``: the space's name and settings, how many specifications and simulation
    configurations, each method's QP backend and the robustness rule."""

    name: str
    n_specifications: int
    n_simulation_configurations: int
    family_size: int
    backend: str
    backends: dict[str, str]
    member_reads_per_member: float
    rule: str
    robust_share: float
    fragile_share: float
    dimensions: tuple[dict[str, Any], ...] = field(default_factory=tuple)
    #: where this run's family members came from: simulated, reused from the member cache,
    #: already complete (resumed); empty for a study written before the member cache
    members: dict[str, int] = field(default_factory=dict)
    #: the run overrides every family of every method was composed with (none of them sets
    #: what the multiverse controls: pipeline.studies.overrides)
    overrides: tuple[str, ...] = ()

    def to_json(self) -> dict:
        data = {f.name: getattr(self, f.name) for f in fields(self)}
        data["dimensions"] = list(self.dimensions)
        data["overrides"] = list(self.overrides)
        return data

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> MultiverseInfo:
        names = {f.name for f in fields(cls)}
        values: dict[str, Any] = {k: (tuple(v) if k in ("dimensions", "overrides") else v)
                                  for k, v in data.items() if k in names}
        return cls(**values)


@dataclass(frozen=True)
class ReadingFlip:
    """A registered reading under which a claim's outcome differs from the default
    specification's: the multiverse's one-at-a-time specification that sets ``dimension``
    to ``value`` (everything else at its default)."""

    claim: str
    comparison: str
    dimension: str
    value: str
    outcome: str
    estimate: float
    default_outcome: str

    @property
    def words(self) -> str:
        """``controller.path_reference = pursuit at 4.0 m (clipped): supported``."""
        return f"{self.dimension} = {self.value}: {self.outcome}"


@dataclass(frozen=True)
class MultiverseResult:
    """Everything :func:`pipeline.studies.multiverse.run_multiverse` found (see the module
    docstring); ``folder`` is where it was read from (None before it is written)."""

    info: MultiverseInfo
    design: pd.DataFrame
    specifications: pd.DataFrame
    robustness: pd.DataFrame
    dimensions: pd.DataFrame
    folder: Path | None = None

    @staticmethod
    def write_design(folder: Path, design: pd.DataFrame) -> None:
        """The design alone, before any run (what an interrupted study resumes from); the
        folder is not trusted until :meth:`write` ends. A trusted result with this very
        design is left as it is (a rerun that changes nothing rewrites nothing)."""
        path = Path(folder) / DESIGN
        if check(Path(folder), "multiverse", required=FILES) is None \
                and path.read_bytes() == csv_text(design).encode("utf-8"):
            return
        Path(folder).mkdir(parents=True, exist_ok=True)
        untrust(folder)
        write_csv_atomic(Path(folder) / DESIGN, design)

    def write(self, folder: Path) -> MultiverseResult:
        """Write the tables and ``space.json``, then the manifest (last)."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        untrust(folder)
        write_csv_atomic(folder / DESIGN, self.design)
        write_csv_atomic(folder / SPECIFICATIONS, self.specifications)
        write_csv_atomic(folder / ROBUSTNESS, self.robustness)
        write_csv_atomic(folder / DIMENSIONS, self.dimensions)
        write_json_atomic(folder / SPACE, self.info.to_json())
        write_manifest(folder, "multiverse", FILES, self.info.name)
        return MultiverseResult(self.info, self.design, self.specifications, self.robustness,
                                self.dimensions, folder)

    #: space.json's bookkeeping of the run that wrote it (where its members came from, how
    #: often each was read): a rerun that finds the result unchanged keeps the first run's
    BOOKKEEPING = ("members", "member_reads_per_member")

    def unchanged_in(self, folder: Path) -> bool:
        """Whether ``folder`` already holds this result, trusted: every table byte for byte
        and ``space.json`` the same but for its :data:`BOOKKEEPING` (a rerun of a complete
        study then rewrites nothing)."""
        import json

        folder = Path(folder)
        if check(folder, "multiverse", required=FILES) is not None:
            return False
        for name, table in zip(FILES[:4], (self.design, self.specifications,
                                           self.robustness, self.dimensions), strict=True):
            if (folder / name).read_bytes() != csv_text(table).encode("utf-8"):
                return False
        try:
            stored = json.loads((folder / SPACE).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        mine = json.loads(json.dumps(self.info.to_json(), allow_nan=False))
        return isinstance(stored, dict) and all(
            {k: v for k, v in data.items() if k not in self.BOOKKEEPING}
            == {k: v for k, v in mine.items() if k not in self.BOOKKEEPING}
            for data in (stored,))

    @staticmethod
    def present(folder: Path | None) -> bool:
        """Whether ``folder`` holds a multiverse's result (trusted or not)."""
        return folder is not None and (Path(folder) / ROBUSTNESS).is_file()

    @classmethod
    def load(cls, folder: Path) -> MultiverseResult:
        """The result in ``folder``; :class:`ResultError` when it cannot be trusted."""
        folder = Path(folder)
        reason = check(folder, "multiverse", required=FILES)
        if reason:
            raise ResultError(f"multiverse tables not trusted: {reason}")
        try:
            tables = {name: pd.read_csv(folder / name) for name in FILES[:4]}
        except (OSError, ValueError) as exc:
            raise ResultError(f"multiverse tables cannot be read ({exc})") from None
        return cls(MultiverseInfo.from_json(read_json(folder / SPACE)), tables[DESIGN],
                   tables[SPECIFICATIONS], tables[ROBUSTNESS], tables[DIMENSIONS], folder)

    def reading_flips(self, register_keys: set[str] | frozenset[str]
                      ) -> tuple[ReadingFlip, ...]:
        """Every claim and comparison whose outcome changes under a registered reading: each
        one-at-a-time specification whose dimension sets a key of ``register_keys`` (the
        interpretation register's) and whose outcome differs from the default
        specification's, in the design's order of dimensions and values."""
        specs = self.specifications
        if specs.empty or "kind" not in specs:
            return ()
        default = specs[specs["kind"] == "default"]
        varied = specs[specs["kind"] == "one_at_a_time"]
        if default.empty:
            return ()
        base = default.iloc[0]
        flips = []
        for dim in self.info.dimensions:
            name = str(dim.get("name") or dim.get("key"))
            keys = {k.strip() for k in str(dim.get("config_key", dim.get("key", ""))).split(",")}
            if name not in specs or not keys & set(register_keys):
                continue
            # every value as text (a missing one reads "nan"), whatever the column's dtype
            text = specs[name].map(str)
            changed = varied[text[varied.index] != str(base[name])]
            for (claim, comparison), default_row in default.groupby(["claim", "comparison"],
                                                                    sort=False):
                before = str(default_row["outcome"].iloc[0])
                rows = changed[(changed["claim"] == claim)
                               & (changed["comparison"] == comparison)]
                for value in dict.fromkeys(text[rows.index]):
                    row = rows[text[rows.index] == value].iloc[0]
                    if str(row["outcome"]) != before:
                        flips.append(ReadingFlip(str(claim), str(comparison), name, value,
                                                 str(row["outcome"]), float(row["estimate"]),
                                                 before))
        return tuple(flips)

    def curve_figure(self, claim_id: str) -> dict[str, Path] | None:
        """The specification curve of ``claim_id`` the command drew, if it is there."""
        if self.folder is None:
            return None
        return figure_files(self.folder / FIGURES, self.curve_stem(claim_id))

    @staticmethod
    def curve_stem(claim_id: str) -> str:
        """The file stem of ``claim_id``'s specification curve."""
        return f"{CURVE_STEM}{claim_id}"

    def figure_folder(self) -> Path:
        """Where the command draws the specification curves."""
        return written(self.folder) / FIGURES
