"""PIDs tuned for the sensors and the latency they run with: the fair baselines.

The paper's gains (Kp = 7, Ki = 40, Kd = 0.05) were tuned on the human knee, read exactly.
A device reads its own encoder, behind the compliant straps, and a perturbed twin reads its
sensors 10 ms late; running the paper's gains there compares a controller with a PID tuned
for another plant. Each entry is the classic Ziegler-Nichols table applied to the ultimate
gain and period that ``myoexo twin tune-pid`` measured on the twin (level 1, nominal subject, as
the paper tuned), with that setting's feedback and latency.

The entries are data, not code: ``myoexo twin tune-pid ... --write NAME`` writes the tuner's
record with its provenance (the command, the twin version, the package versions, the date)
to ``myoexo/assets/fits/pid_tuned_NAME.json``, and :data:`TUNED_PIDS` reads every such file.

A controller spec selects one with ``pid:tuned=NAME`` (``myoexo evaluate --controllers
pid:tuned=exo``); the entry sets the gains and the feedback, and any other PID option
(``ramp_s``, ``limit``, explicit gains) still applies on top.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.control.pid import PIDGains
from myoexo.runtime import fits

#: The tuned PIDs are the package's fits ``pid_tuned_<name>`` (:mod:`myoexo.runtime.fits`).
_PREFIX = "pid_tuned_"

#: What each tuning is the fair baseline of (documentation; the numbers are in the files).
TUNED_PID_USES: dict[str, str] = {
    "exo": "the device PID: what the exoskeleton measures, its encoder",
    "latency": "the perturbed twins: the human knee read 10 ms late",
}


@dataclass(frozen=True)
class TunedPID:
    """One Ziegler-Nichols tuning of the knee PID, as its file records it.

    Attributes:
        name: The spec's ``tuned=`` value.
        feedback: What the PID reads: ``"knee"`` (the human knee) or ``"exo"`` (the exo
            encoder).
        latency_s: Sensor latency of the tuning twin (s).
        ultimate_gain_per_rad: ``Ku`` measured by the P-only search (1/rad).
        ultimate_period_s: ``Tu`` at ``Ku`` (s).
        gains: The classic table's gains for ``Ku, Tu``.
        record: The file, relative to the package (``assets/fits/pid_tuned_NAME.json``).
        command: The command that wrote it.
        twin_version: The twin version it was tuned on.
        use: The setting it is the fair baseline of.
    """

    name: str
    feedback: str
    latency_s: float
    ultimate_gain_per_rad: float
    ultimate_period_s: float
    gains: PIDGains
    record: str
    command: str
    twin_version: int
    use: str

    @classmethod
    def from_fit(cls, name: str) -> TunedPID:
        """The tuned PID *name* as the package's fit ``pid_tuned_<name>`` holds it."""
        doc = fits.read_fit(f"{_PREFIX}{name}")
        result, provenance = doc["result"], doc["provenance"]
        return cls(
            name=name,
            feedback=str(result["settings"]["feedback"]),
            latency_s=float(result["settings"].get("latency_s", 0.0)),
            ultimate_gain_per_rad=float(result["ultimate_gain_per_rad"]),
            ultimate_period_s=float(result["ultimate_period_s"]),
            gains=PIDGains(**result["zn_gains"]),
            record="/".join((*fits.FITS_PACKAGE_DIR, f"{_PREFIX}{name}.json")),
            command=str(provenance["command"]),
            twin_version=int(provenance["twin_version"]),
            use=TUNED_PID_USES.get(name, ""),
        )


def write_tuned_pid(name: str, result: dict[str, Any], provenance: dict[str, Any]) -> Path:
    """Write a tuner's *result* (``TuningResult.to_dict()``) with its *provenance* as the
    tuned PID *name*; returns the file."""
    return fits.write_fit(f"{_PREFIX}{name}", result, provenance)


def _load() -> dict[str, TunedPID]:
    names = sorted(p.stem[len(_PREFIX) :] for p in fits.fits_dir().glob(f"{_PREFIX}*.json"))
    return {name: TunedPID.from_fit(name) for name in names}


#: The tuned PIDs by name (``pid:tuned=NAME``), read from the package's files.
TUNED_PIDS: dict[str, TunedPID] = _load()


def tuned_pid(name: str) -> TunedPID:
    """The entry of :data:`TUNED_PIDS` called *name*.

    Raises:
        ValueError: *name* is not one of them (the message lists them).
    """
    try:
        return TUNED_PIDS[name]
    except KeyError:
        raise ValueError(f"tuned PID {name!r} is unknown; accepted: {sorted(TUNED_PIDS)}") from None


def tuned_pids_markdown() -> str:
    """The table of :data:`TUNED_PIDS` beside the paper's gains (for the documentation)."""
    paper = PIDGains()
    rows = [
        "| spec | reads | latency (ms) | Ku (1/rad) | Tu (s) | Kp | Ki | Kd "
        "| the fair baseline of |",
        "|---|---|---|---|---|---|---|---|---|",
        f"| `pid` | human knee | 0 | - | - | {paper.kp:g} | {paper.ki:g} | {paper.kd:g} | "
        "the paper's gains (tuned by its authors at level 1) |",
    ]
    for t in TUNED_PIDS.values():
        g = t.gains
        reads = "exo encoder" if t.feedback == "exo" else "human knee"
        rows.append(
            f"| `pid:tuned={t.name}` | {reads} | {1000 * t.latency_s:g} | "
            f"{t.ultimate_gain_per_rad:.2f} | {t.ultimate_period_s:.3f} | {g.kp:.2f} | "
            f"{g.ki:.1f} | {g.kd:.3f} | {t.use} |"
        )
    return "\n".join(rows) + "\n"
