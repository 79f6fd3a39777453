"""The studies: experiments that drive the whole stack (the twin, the reflex, the controllers,
training and the evaluation protocol), each a command, on the top floor of the package
(``docs/architecture.md``):

* :mod:`~myoexo.studies.demo` (``myoexo demo``, what ``make demo`` runs): the evaluation
  protocol, small: one table and a paragraph of what it found;
* :mod:`~myoexo.studies.calibrate` (``myoexo twin calibrate``): fits the stretch reflex (or the
  after-discharge) so that the paper's PID behaves as in the study;
* :mod:`~myoexo.studies.fit_subject` (``myoexo twin fit-subject``): a personal twin fitted
  to one patient's clinical recordings with CMA-ES, with each parameter's interval and what
  the recordings cannot identify;
* :mod:`~myoexo.studies.frontier` (``myoexo frontier``): the trade-off between interaction
  torque and settling per level, shaped PIDs, policies and the oracle;
* :mod:`~myoexo.studies.distill` (``myoexo policy distill``): DAgger distillation of the full-state
  teacher into the exo-sensor student;
* :mod:`~myoexo.studies.sweep` (``myoexo policy sweep``): Ray Tune over training configurations,
  ranked on the acceptance criteria.

Nothing is imported here: each study loads what it drives when it is imported.
"""
