"""roadview application: CLI, pipeline, compositor, evaluation.

It composes camera_cal, lanes and vehicles, which never import it.
"""
