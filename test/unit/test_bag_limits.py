"""bag_limits: what a bag's files may declare before rosbags decompresses them."""
from __future__ import annotations

import os
from pathlib import Path
import shutil
import struct

from helpers import find_bag
import pytest
from ssm_localization import BagError, read_bag
from ssm_localization.io.bag_limits import (check_compressed_file, check_mcap_chunks,
                                            MCAP_MAGIC)
import zstandard                                # a dependency of rosbags


def _chunk_bomb(path: Path, declared: int) -> Path:
    """Write an mcap of one zstd chunk declaring ``declared`` bytes, holding 1 KB of zeros."""
    payload = zstandard.ZstdCompressor().compress(bytes(1024))
    compression = b'zstd'
    content = (struct.pack('<QQQI', 0, 0, declared, 0) + struct.pack('<I', len(compression))
               + compression + struct.pack('<Q', len(payload)) + payload)
    path.write_bytes(MCAP_MAGIC + struct.pack('<BQ', 0x06, len(content)) + content)
    return path


def test_the_committed_bags_pass_and_a_chunk_bomb_is_refused_unread(tmp_path):
    for name in ('intel_queries', 'depot_sim', 'intel_track'):
        bag = find_bag(name)
        assert all(check_mcap_chunks(p) >= 1 for p in bag.glob('*.mcap'))
    bomb = _chunk_bomb(tmp_path / 'bomb.mcap', 10 ** 9)
    with pytest.raises(BagError, match='declares 1000000000 bytes uncompressed'):
        check_mcap_chunks(bomb)
    with pytest.raises(BagError, match='refused before decompressing'):
        read_bag(bomb)
    assert check_mcap_chunks(_chunk_bomb(tmp_path / 'fine.mcap', 1024)) == 1


def test_a_fifo_among_a_bags_files_is_refused_not_waited_on(tmp_path):
    bag = tmp_path / 'bag'
    shutil.copytree(find_bag('depot_sim'), bag)
    mcap = next(bag.glob('*.mcap'))
    mcap.unlink()
    os.mkfifo(mcap)
    with pytest.raises(BagError, match='not a regular file'):
        read_bag(bag)
    (bag / 'metadata.yaml').unlink()           # a folder of one .mcap, no metadata
    with pytest.raises(BagError, match='not a regular file'):
        read_bag(bag)


@pytest.mark.parametrize('with_size', [True, False])
def test_a_file_compressed_whole_may_not_expand_without_bound(tmp_path, with_size):
    """The frame header's size when it has one, else a count in memory; nothing written."""
    path = tmp_path / 'x.mcap.zstd'
    data = bytes(4 << 20)
    if with_size:
        path.write_bytes(zstandard.ZstdCompressor().compress(data))
    else:
        with path.open('wb') as fh, zstandard.ZstdCompressor().stream_writer(fh) as out:
            out.write(data)
    assert check_compressed_file(path) == len(data)               # within 1 GiB
    with pytest.raises(BagError, match='decompression bomb'):
        check_compressed_file(path, free=1 << 20, ratio=100)
