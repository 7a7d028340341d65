"""sashil.writer: what a run leaves and the one writer of it, a layer of its own between the
engine's runs and the recording they stream.

:class:`~sashil.writer.run_folder.RunFolder` is a run's folder; the engine and the verbs emit a
run's documents (:mod:`sashil.writer.documents`: start, progress, stop) to their subscribers;
:class:`~sashil.writer.folder_writer.FolderWriter` subscribes to them and writes the folder;
:mod:`sashil.writer.summary_writer` is the one place ``config.yaml`` and ``summary.json`` are
written. Nothing below this layer writes either file.
"""
