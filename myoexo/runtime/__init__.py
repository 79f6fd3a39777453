"""What keeps long runs safe, independent of the twin: atomic files and the versions of a run
(:mod:`~myoexo.runtime.files`), folder locks, graceful SIGTERM/SIGINT stops and workers that
die with their driver (:mod:`~myoexo.runtime.lifecycle`), and joining or starting a Ray
cluster (:mod:`~myoexo.runtime.ray_cluster`; imports Ray only when used)."""
