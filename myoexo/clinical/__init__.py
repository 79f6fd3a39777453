"""Clinical spasticity tests on the twin: Tardieu, Wartenberg pendulum, Modified Ashworth.

Each test is a function returning a result (``table()`` per level, ``traces``), a figure
function (a pyplot-free ``matplotlib.figure.Figure``) and a CLI command:

* ``myoexo clinic tardieu``: :func:`~myoexo.clinical.tardieu.run_tardieu`, catch angle R1 at a
  fast stretch, passive range R2 at a slow one (:mod:`myoexo.clinical.tardieu`);
* ``myoexo clinic pendulum``: :func:`~myoexo.clinical.pendulum.run_pendulum`, Wartenberg's
  pendulum test, relaxation index (:mod:`myoexo.clinical.pendulum`);
* ``myoexo clinic mas``: :func:`~myoexo.clinical.mas.run_mas_exam`, the Modified Ashworth
  examination's resistance profile (:mod:`myoexo.clinical.mas`);
* :func:`~myoexo.clinical.hold.run_stretch_hold` (``myoexo clinic hold``): a
  fast and a slow stretch, each then held: does the resistance outlast the stretch
  (:mod:`myoexo.clinical.hold`)?
* :mod:`myoexo.clinical.recording`: a patient's clinical tests as files (one CSV per test):
  :func:`~myoexo.clinical.recording.read_recording` (refuses a bad file in one line),
  :func:`~myoexo.clinical.recording.write_recording`, and
  :func:`~myoexo.clinical.recording.record_from_twin`, a synthetic recording of a test on
  the twin (``myoexo clinic record``; ``myoexo clinic check-recording`` checks files).

Every function takes ``reflex`` (a preset name, ``"stretch"`` by default, or a
:class:`~myoexo.spasticity.ReflexModel`) so the reflex models can be compared side by side,
and runs the nominal Table I subject of each level unless ``subjects`` gives individual ones.
The shared machinery (the exo-driven knee, the options the commands share) is
:mod:`myoexo.clinical.common`, which :mod:`myoexo.clinical.stretch` uses too.

The submodules are imported on first use (``myoexo.clinical.run_tardieu`` works), so
importing this package stays cheap and free of import cycles with :mod:`myoexo.clinical.stretch`.
"""

from __future__ import annotations

from myoexo.runtime.lazy import lazy_exports

__all__ = [
    "MASExamParams",
    "MASExamResult",
    "PendulumParams",
    "PendulumResult",
    "Recording",
    "SensorNoise",
    "StretchHoldParams",
    "StretchHoldResult",
    "TardieuParams",
    "TardieuResult",
    "plot_mas_exam",
    "plot_pendulum",
    "plot_tardieu",
    "read_recording",
    "record_from_twin",
    "run_mas_exam",
    "run_pendulum",
    "run_stretch_hold",
    "run_tardieu",
    "write_recording",
]

_HOMES = {
    "TardieuParams": "tardieu",
    "TardieuResult": "tardieu",
    "plot_tardieu": "tardieu",
    "run_tardieu": "tardieu",
    "PendulumParams": "pendulum",
    "PendulumResult": "pendulum",
    "plot_pendulum": "pendulum",
    "run_pendulum": "pendulum",
    "MASExamParams": "mas",
    "MASExamResult": "mas",
    "plot_mas_exam": "mas",
    "run_mas_exam": "mas",
    "StretchHoldParams": "hold",
    "StretchHoldResult": "hold",
    "run_stretch_hold": "hold",
    "Recording": "recording",
    "SensorNoise": "recording",
    "read_recording": "recording",
    "record_from_twin": "recording",
    "write_recording": "recording",
}

__getattr__, __dir__ = lazy_exports(__name__, _HOMES)
