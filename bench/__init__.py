"""Benchmarks for roadview (`make bench`): speed per stage, end to end, and memory."""
