"""sashil.engine: a run assembled once from its config, and the one rule for where its loop runs.

:func:`assemble` is the only reader of a run's config: it hands each component its parts as plain
values (:class:`~sashil.config.parts.RunSpec`). :func:`run` runs a verb's plan, and
:func:`loop_in_process` decides, for every plan and every verb, whether its loop runs in a process
of its own or in this one.
"""

from sashil.engine.assemble import assemble
from sashil.engine.running import run
from sashil.engine.where import loop_in_process

__all__ = ["assemble", "loop_in_process", "run"]
