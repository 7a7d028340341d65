"""sashil.engine: a run's config resolved and checked, its run assembled once, the one rule for
where its loop runs, and the one way a verb runs a loop.

:func:`~sashil.engine.resolve.resolve` turns where a config comes from into the read-only config a
verb runs with, checked by the schema and by what the components declare.
:func:`assemble` is the only reader of a run's config: it hands each component its parts as plain
values (:class:`~sashil.config.parts.RunSpec`). :func:`run` runs a verb's plan, and
:func:`loop_in_process` decides, for every plan and every verb, whether its loop runs in a process
of its own or in this one; :func:`run` launches a session's loop too (``session=``), by the same rule.
Each is imported here by name, so a reader (or a tool) follows
``engine.run`` to its module.
"""

from __future__ import annotations

from sashil.engine.assemble import assemble, assembled
from sashil.engine.running import Session, SessionFolder, StartedLoop, run
from sashil.engine.where import loop_in_process

__all__ = ["Session", "SessionFolder", "StartedLoop", "assemble", "assembled", "loop_in_process", "run"]
