"""Developer tools (the loader fuzzer); never imported by ``import clrt``."""
