"""PIDs tuned for the sensors and the latency they run with: the fair baselines.

The paper's gains (Kp = 7, Ki = 40, Kd = 0.05) were tuned on the human knee, read exactly.
A device reads its own encoder, behind the compliant straps, and a perturbed twin reads its
sensors 10 ms late; running the paper's gains there compares a controller with a PID tuned
for another plant. Each entry below is the classic Ziegler-Nichols table applied to the
ultimate gain and period that ``myoexo tune-pid`` measured on the twin (level 1, nominal
subject, as the paper tuned), with that setting's feedback and latency. The tuner's output is
committed under ``docs/studies/pid_tuning/`` and ``tests/test_tuned_pid.py`` ties each entry
to its record.

A controller spec selects one with ``pid:tuned=NAME`` (``myoexo evaluate --controllers
pid:tuned=exo``); the entry sets the gains and the feedback, and any other PID option
(``ramp_s``, ``limit``, explicit gains) still applies on top.
"""

from __future__ import annotations

from dataclasses import dataclass

from myoexo.control.pid import PIDGains


@dataclass(frozen=True)
class TunedPID:
    """One Ziegler-Nichols tuning of the knee PID.

    Attributes:
        name: The spec's ``tuned=`` value.
        feedback: What the PID reads: ``"knee"`` (the human knee) or ``"exo"`` (the exo
            encoder).
        latency_s: Sensor latency of the tuning twin (s).
        ultimate_gain_per_rad: ``Ku`` measured by the P-only search (1/rad).
        ultimate_period_s: ``Tu`` at ``Ku`` (s).
        gains: The classic table's gains for ``Ku, Tu``.
        record: The tuner's JSON output, relative to the repository.
        command: The command that wrote ``record``.
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
    use: str


#: The tuned PIDs by name (``pid:tuned=NAME``).
TUNED_PIDS: dict[str, TunedPID] = {
    t.name: t
    for t in (
        TunedPID(
            name="exo",
            feedback="exo",
            latency_s=0.0,
            ultimate_gain_per_rad=14.67206469127474,
            ultimate_period_s=0.171670454031595,
            gains=PIDGains(kp=8.803238814764843, ki=102.55974290304673, kd=0.1889070005349051),
            record="docs/studies/pid_tuning/exo.json",
            command="myoexo tune-pid --feedback exo --out docs/studies/pid_tuning/exo.json",
            use="the device PID: what the exoskeleton measures, its encoder",
        ),
        TunedPID(
            name="latency",
            feedback="knee",
            latency_s=0.010,
            ultimate_gain_per_rad=3.018328855186846,
            ultimate_period_s=0.19734358900140975,
            gains=PIDGains(kp=1.8109973131121075, ki=18.353748629748196, kd=0.04467358868018164),
            record="docs/studies/pid_tuning/latency.json",
            command="myoexo tune-pid --latency-ms 10 --out docs/studies/pid_tuning/latency.json",
            use="the perturbed twins: the human knee read 10 ms late",
        ),
    )
}


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
