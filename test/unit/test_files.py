"""
files/: bounded reads.

The alias-bomb-proof YAML loader, atomic outputs that leave nothing behind on failure.
"""
from __future__ import annotations

import os

import pytest
from ssm_localization.files.reading import clip, echo, input_file, read_bounded
from ssm_localization.files.writing import (atomic_dir, atomic_files, check_output_dir,
                                            check_output_file)
from ssm_localization.files.yaml_input import (BoundedSafeLoader, expanded_size, load_yaml_file,
                                               parse_yaml, YamlBombError)
import yaml


def laughs(levels: int) -> str:
    lines = ['a0: &a0 [x, x, x, x, x, x, x, x, x, x]']
    lines += [f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 10) + ']' for i in range(1, levels)]
    return '\n'.join(lines) + '\n'


# ------------------------------------------------------------------ reading

def test_clip_folds_lines_and_bounds_the_length():
    assert clip('a\n  b\tc') == 'a b c'
    long = clip('x' * 10**7, 50)
    assert len(long) == 50 and long.endswith('...')


def test_echo_bounds_deeply_nested_and_long_values():
    value = [[[[['deep'] * 1000]]]] * 1000
    text = echo(value)
    assert len(text) <= 200 and '...' in text


def test_input_file_names_what_is_wrong(tmp_path):
    with pytest.raises(FileNotFoundError, match='params file not found'):
        input_file(tmp_path / 'nope.yaml', 'params file')
    with pytest.raises(ValueError, match='is a directory'):
        input_file(tmp_path, 'params file')
    with pytest.raises(ValueError, match='not a regular file'):
        input_file('/dev/zero', 'params file')


def test_read_bounded_refuses_large_files_and_reports_read_errors(tmp_path):
    f = tmp_path / 'big.yaml'
    f.write_bytes(b'x' * 101)
    assert read_bounded(f, 'f', 101) == b'x' * 101
    with pytest.raises(ValueError, match='larger than 100 bytes'):
        read_bounded(f, 'f', 100)
    with pytest.raises(ValueError, match='cannot read'):   # EIO even as root
        read_bounded('/proc/self/mem', 'f', 100)


# ------------------------------------------------------------------ YAML

def test_plain_documents_load_as_with_safe_load():
    text = 'a: 1\nb: [1, 2, {c: d}]\nbase: &b {x: 1}\nderived: {<<: *b, y: 2}\n'
    assert parse_yaml(text, 't') == yaml.safe_load(text)
    assert parse_yaml('', 't') is None


def test_aliases_are_counted_expanded():
    node = yaml.compose(laughs(3))
    # the mapping, its 3 keys, a0 (1 + 10), a1 (1 + 10 * 11), a2 (1 + 10 * 111)
    assert expanded_size(node) == 1 + 3 + 11 + 111 + 1111
    with pytest.raises(YamlBombError):
        expanded_size(node, limit=1236)


def test_billion_laughs_are_refused_quickly():
    with pytest.raises(ValueError, match=r'more than 100000 nodes \(aliases expanded\)'):
        parse_yaml(laughs(9), 'bomb.yaml')
    with pytest.raises(YamlBombError):
        yaml.load(laughs(9), Loader=BoundedSafeLoader)
    parse_yaml(laughs(4), 'fine.yaml')          # 1111 expanded nodes: allowed


def test_recursive_aliases_deep_nesting_and_python_tags_are_refused():
    with pytest.raises(ValueError, match='contains it'):
        parse_yaml('a: &a [1, *a]\n', 'r.yaml')
    with pytest.raises(ValueError, match='nested too deeply'):
        parse_yaml('[' * 50000, 'deep.yaml')
    with pytest.raises(ValueError, match='malformed YAML'):
        parse_yaml('!!python/object/apply:os.system ["true"]\n', 'evil.yaml')


@pytest.mark.parametrize('text', ['a: !!bool maybe\n', 'a: !!timestamp nope\n', 'a: !!int abc\n',
                                  'a: !!float abc\n', 'a: 2001-13-45\n', 'a: ' + '9' * 5000])
def test_values_the_safe_constructors_cannot_read_are_one_error_naming_the_file(text):
    """Turn SafeLoader's KeyError, AttributeError or ValueError for these into one ValueError."""
    with pytest.raises(ValueError, match=r'^odd\.yaml: malformed YAML: a value cannot be read'):
        parse_yaml(text, 'odd.yaml')


def test_load_yaml_file_bounds_size_and_clips_messages(tmp_path):
    f = tmp_path / 'p.yaml'
    f.write_text('a: [' + 'x, ' * 10000 + '\n')      # unterminated flow sequence
    with pytest.raises(ValueError) as info:
        load_yaml_file(f, 'params file')
    assert str(info.value).startswith(f'params file {f}: malformed YAML')
    assert len(str(info.value)) < 400
    f.write_text('#' * 200)
    with pytest.raises(ValueError, match='larger than 100 bytes'):
        load_yaml_file(f, 'params file', max_bytes=100)


# ------------------------------------------------------------------ writing

def test_output_checks(tmp_path):
    (tmp_path / 'file').write_text('x')
    assert check_output_file(tmp_path / 'new' / 'deeper' / 'out.csv', 'out') \
        == tmp_path / 'new' / 'deeper' / 'out.csv'
    with pytest.raises(ValueError, match='is a directory'):
        check_output_file(tmp_path, 'out')
    with pytest.raises(ValueError, match='file is not a directory'):
        check_output_file(tmp_path / 'file' / 'out.csv', 'out')
    with pytest.raises(ValueError, match='not a regular file'):
        check_output_file('/dev/null', 'out')
    with pytest.raises(FileExistsError, match='exists already'):
        check_output_dir(tmp_path / 'file', 'bag', overwrite=False)
    with pytest.raises(ValueError, match='not a directory'):
        check_output_dir(tmp_path / 'file', 'folder')
    check_output_dir(tmp_path / 'file', 'bag', overwrite=True)
    assert not (tmp_path / 'new').exists()          # checks create nothing


def test_atomic_files_commit_all_together(tmp_path):
    a, b = tmp_path / 'sub' / 'a.txt', tmp_path / 'sub' / 'b.txt'
    with atomic_files(a, b) as (ta, tb):
        ta.write_text('A')
        tb.write_text('B')
        assert ta.suffix == '.txt' and not a.exists()
    assert (a.read_text(), b.read_text()) == ('A', 'B')
    assert sorted(p.name for p in a.parent.iterdir()) == ['a.txt', 'b.txt']


def test_atomic_files_leave_nothing_behind_on_failure(tmp_path):
    target = tmp_path / 'x' / 'y' / 'out.npz'
    with pytest.raises(RuntimeError):
        with atomic_files(target) as (tmp,):
            tmp.write_bytes(b'partial')
            raise RuntimeError('writer failed')
    assert list(tmp_path.iterdir()) == []           # no temporary file, no created directory
    existing = tmp_path / 'keep.csv'
    existing.write_text('old')
    with pytest.raises(ValueError, match='cannot write'):
        with atomic_files(existing) as (tmp,):
            tmp.write_text('new')
            raise OSError(28, 'No space left on device')
    assert existing.read_text() == 'old' and list(tmp_path.iterdir()) == [existing]


def test_atomic_files_refuse_the_same_target_twice(tmp_path):
    with pytest.raises(ValueError, match='named twice'):
        with atomic_files(tmp_path / 'm.pgm', tmp_path / '.' / 'm.pgm'):
            pass


def test_atomic_dir_replaces_only_when_complete(tmp_path):
    bag = tmp_path / 'bag'
    with atomic_dir(bag, 'bag') as stage:
        stage.mkdir()
        (stage / 'metadata.yaml').write_text('v: 1')
    assert (bag / 'metadata.yaml').read_text() == 'v: 1'
    with pytest.raises(RuntimeError):
        with atomic_dir(bag, 'bag', overwrite=True) as stage:
            stage.mkdir()
            (stage / 'metadata.yaml').write_text('v: 2')
            raise RuntimeError
    assert (bag / 'metadata.yaml').read_text() == 'v: 1'
    assert sorted(os.listdir(tmp_path)) == ['bag']
    with atomic_dir(bag, 'bag', overwrite=True) as stage:
        stage.mkdir()
        (stage / 'metadata.yaml').write_text('v: 3')
    assert (bag / 'metadata.yaml').read_text() == 'v: 3'
    assert sorted(os.listdir(tmp_path)) == ['bag']
