"""The files clrt writes: images (every format in one table), arrays and tables.

``writers.py`` holds the table of formats (:data:`WRITERS`: what each can hold,
how it is written and recognised) and the one rule of every file clrt writes
-- through a temporary file and a rename, with the record of its SHA-256
beside it, and never over a file that is not exactly what clrt wrote unless
asked (``force``).  ``files.py`` does the writing itself and judges a file by
its content (``file_state``); ``png.py``, ``pillow.py`` and ``exr.py`` the
formats.
"""

from clrt.output.exr import EXR_INSTALL_HINT, EXR_MARK_ATTRIBUTE, exr_layers, require_exr
from clrt.output.files import (ABSENT, CHANGED, FOREIGN, NOT_A_FILE, OURS, RECORD_PREFIX, RECORD_SUFFIX, SOFTWARE_MARK,
                               file_state, record_path, remove_written)
from clrt.output.png import PNG_COMPRESS_LEVEL, png_bytes
from clrt.output.writers import (BIT_DEPTHS, CHANNELS, DEPTHS, FORMAT_NAMES, IMAGE_SUFFIXES, IMAGE_WRITERS, WRITERS,
                                 Writer, check_bit_depth, check_replace, encode_srgb, format_writer, image_pixels,
                                 linear_depth, render_writer, write_array, write_exr, write_file, write_image,
                                 writer_for, written_by_clrt)

__all__ = ["ABSENT", "BIT_DEPTHS", "CHANGED", "CHANNELS", "DEPTHS", "EXR_INSTALL_HINT", "EXR_MARK_ATTRIBUTE",
           "FOREIGN", "FORMAT_NAMES", "IMAGE_SUFFIXES", "IMAGE_WRITERS", "NOT_A_FILE", "OURS", "PNG_COMPRESS_LEVEL",
           "RECORD_PREFIX", "RECORD_SUFFIX", "SOFTWARE_MARK", "WRITERS", "Writer", "check_bit_depth", "check_replace",
           "encode_srgb", "exr_layers", "file_state", "format_writer", "image_pixels", "linear_depth", "png_bytes",
           "record_path", "remove_written", "render_writer", "require_exr", "write_array", "write_exr", "write_file",
           "write_image", "writer_for", "written_by_clrt"]
