"""
What a bag's files may declare before ``rosbags`` decompresses them.

A bag is untrusted input, and both ways rosbag2 compresses one decompress without a cap in
``rosbags``: an mcap chunk declares its uncompressed size, and 30 KB of zstd declaring 10^9
zero bytes took 2 GB and ran on in a loop over empty records; a bag compressed per file
(``compression_mode: FILE``) is decompressed into a temporary file first, and 61 KB filled 1.9 GB
of ``$TMPDIR``. :func:`check_bag_files` looks before that happens: every file the bag lists must
be a regular file (a FIFO blocks the reader for ever), no mcap chunk may declare more than
:data:`MAX_CHUNK_BYTES` (the records are walked by their headers, with seeks), and a file
compressed whole may expand to at most :data:`MAX_FILE_RATIO` times its size beyond
:data:`FREE_FILE_BYTES` (its zstd frame header says how much, or it is streamed and counted in
memory, never written).
"""
from __future__ import annotations

from pathlib import Path
import struct

import zstandard                        # a dependency of rosbags, which reads the bags

from .bag_records import BagError

#: largest uncompressed mcap chunk: a /map message of 250 M cells (the node's default limit is
#: 36 M); rosbag2 writes chunks of about 1 MB, and a message larger than that gets a chunk of its
#: own
MAX_CHUNK_BYTES = 256 << 20
#: a file compressed whole may expand to this many bytes whatever its size ...
FREE_FILE_BYTES = 1 << 30
#: ... and beyond that to at most this many times its compressed size
MAX_FILE_RATIO = 200

MCAP_MAGIC = b'\x89MCAP0\r\n'
_CHUNK = 0x06
_ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'


def check_bag_files(files: list[Path], file_compressed: bool) -> None:
    """Refuse what would block, or expand without bound, once ``rosbags`` opens ``files``."""
    for path in files:
        if not path.exists():
            continue                # rosbags names the missing file
        if not path.is_file():
            raise BagError(f'{path}: not a regular file (a FIFO or a device would block)')
        if file_compressed or path.suffix == '.zstd':
            check_compressed_file(path)
        elif path.suffix == '.mcap':
            check_mcap_chunks(path)


def check_mcap_chunks(path: Path, max_chunk: int = MAX_CHUNK_BYTES) -> int:
    """
    Return the number of chunks of an mcap file after checking their declared sizes.

    Walks the records by their headers (opcode, length) from the magic on and stops quietly
    at the end of what is there (a file cut short is the reader's business).
    """
    chunks = 0
    with path.open('rb') as fh:
        if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            return 0                # not mcap: the reader says so
        size = path.stat().st_size
        at = len(MCAP_MAGIC)
        while at + 9 <= size:
            fh.seek(at)
            opcode, length = struct.unpack('<BQ', fh.read(9))
            if opcode == _CHUNK:
                head = fh.read(28)
                if len(head) < 28:
                    break
                uncompressed = struct.unpack_from('<Q', head, 16)[0]
                if uncompressed > max_chunk:
                    raise BagError(f'{path}: a chunk at byte {at} declares {uncompressed} bytes '
                                   f'uncompressed (more than {max_chunk}): refused before '
                                   f'decompressing it')
                chunks += 1
            at += 9 + length
    return chunks


def check_compressed_file(path: Path, free: int = FREE_FILE_BYTES,
                          ratio: int = MAX_FILE_RATIO) -> int:
    """Return the size a zstd-compressed bag file expands to, refusing one that expands too far."""
    size = path.stat().st_size
    limit = max(free, ratio * size)
    with path.open('rb') as fh:
        head = fh.read(18)
        if not head.startswith(_ZSTD_MAGIC):
            return size             # not zstd: the reader says so
        try:
            declared = zstandard.get_frame_parameters(head).content_size
        except zstandard.ZstdError:
            declared = zstandard.CONTENTSIZE_UNKNOWN
        if declared not in (zstandard.CONTENTSIZE_UNKNOWN, zstandard.CONTENTSIZE_ERROR):
            total = declared
        else:
            fh.seek(0)
            total = 0
            reader = zstandard.ZstdDecompressor().stream_reader(fh, read_across_frames=True)
            try:
                while total <= limit:
                    block = reader.read(1 << 20)
                    if not block:
                        break
                    total += len(block)
            except zstandard.ZstdError:
                return size         # corrupt: the reader says so
    if total > limit:
        raise BagError(f'{path}: compressed {size} bytes expand to more than {limit} (a '
                       f'decompression bomb?): refused before decompressing it to disk')
    return total
