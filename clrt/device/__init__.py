"""Stage 3 of the pipeline: OpenCL devices, buffer layouts and kernel programs."""
