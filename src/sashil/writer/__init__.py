"""sashil.writer: the run folder's writer, a layer of its own between the engine's runs and the
recording they stream.

:class:`~sashil.writer.folder_writer.FolderWriter` subscribes to a verb's documents and writes its
folder; :mod:`sashil.writer.summary_writer` is the one place ``config.yaml`` and ``summary.json``
are written. Nothing below this layer writes either file.
"""
