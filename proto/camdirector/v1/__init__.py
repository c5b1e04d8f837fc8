"""camdirector.v1 wire contract: generated from director.proto by ``make proto``.

The generated modules are committed; ``tests/proto/test_generated_current.py`` regenerates them
and fails when they differ from the .proto file.
"""
