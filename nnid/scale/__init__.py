"""Fan-out of train, loop, detect and compare runs over many logs, vehicles, configs and
settings: a manifest (or a sweep) expands into tasks with stable ids
(:mod:`nnid.scale.manifest`), each task calls the library where it lands
(:mod:`nnid.scale.task`), an engine runs them (:mod:`nnid.scale.engines`: local processes by
default, Ray when installed and asked for) and one summary is written
(:mod:`nnid.scale.batch`)."""
