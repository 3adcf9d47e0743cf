"""Documentation that cannot drift: the parameter reference is what the schemas generate, every
relative Markdown link resolves, the README stays short and keeps the two commands, and every
schema parameter is documented. No ROS, no DDS."""
import difflib
import glob
import os
import re

import pytest

from eha_ros.core.config.registry import node_names, schema_for
from eha_ros.tools import param_docs

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(ROOT, 'README.md')
PARAMS_MD = os.path.join(ROOT, 'docs', 'parameters.md')
REGENERATE = '.venv/bin/python -m eha_ros.tools.param_docs'
README_MAX_LINES = 150
# README "The two commands": CI and other tools run exactly these; keep them textually identical
TWO_COMMANDS = (
    './scripts/run     # the main job: sets up if needed, runs the simulated actuator, '
    'writes a report under out/',
    './scripts/test    # sets up if needed, then runs the test suite',
)


def _read(path):
    with open(path, encoding='utf-8') as fh:
        return fh.read()


def markdown_files():
    return [README] + sorted(glob.glob(os.path.join(ROOT, 'docs', '**', '*.md'), recursive=True))


def _rel(path):
    return os.path.relpath(path, ROOT)


# ------------------------------------------------------------------ (a) generated reference

def test_parameters_md_is_what_the_schemas_generate():
    expected = param_docs.render()
    if not os.path.exists(PARAMS_MD):
        pytest.fail(f'docs/parameters.md is missing: generate it with {REGENERATE}')
    current = _read(PARAMS_MD)
    if current != expected:
        diff = list(difflib.unified_diff(current.splitlines(), expected.splitlines(),
                                         'docs/parameters.md', 'generated', n=0, lineterm=''))
        pytest.fail(f'docs/parameters.md differs from the parameter schemas: regenerate it '
                    f'with {REGENERATE} and commit it. First differences:\n'
                    + '\n'.join(diff[:12]))


def test_param_docs_check_flags_a_stale_file(tmp_path, capsys):
    out = tmp_path / 'parameters.md'
    assert param_docs.main(['--check', '--out', str(out)]) == 1           # missing
    out.write_text(param_docs.render(), encoding='utf-8')
    assert param_docs.main(['--check', '--out', str(out)]) == 0
    out.write_text(param_docs.render().replace('| float |', '| int |', 1), encoding='utf-8')
    capsys.readouterr()
    assert param_docs.main(['--check', '--out', str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(out) in err[0] and 'param_docs' in err[0], err
    assert out.read_text(encoding='utf-8') != param_docs.render()           # --check writes nothing


def test_param_docs_error_is_one_line(tmp_path, capsys):
    bad = tmp_path / 'no' / 'such' / 'dir' / 'parameters.md'
    assert param_docs.main(['--out', str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('param_docs: error: ') and str(bad) in err[0], err


# ------------------------------------------------------------------ (b) links

_FENCE = re.compile(r'^\s*(```|~~~)')
_INLINE_LINK = re.compile(r'\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+"[^"]*")?\s*\)')
_REF_DEF = re.compile(r'^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+"[^"]*")?\s*$')
_HEADING = re.compile(r'^\s{0,3}#{1,6}\s+(.*?)\s*#*\s*$')
_SCHEME = re.compile(r'^[A-Za-z][A-Za-z0-9+.-]*:')


def _prose_lines(text):
    """Lines outside fenced code blocks, with inline code spans removed."""
    inside = False
    for line in text.splitlines():
        if _FENCE.match(line):
            inside = not inside
            continue
        if not inside:
            yield re.sub(r'`+[^`]*`+', '', line)


def _slug(heading):
    """GitHub's anchor for a heading: link text only, lower case, punctuation dropped."""
    text = re.sub(r'\[([^\]]*)\]\([^)]*\)', r'\1', heading).lower()
    return re.sub(r'[^\w\- ]', '', text).replace(' ', '-')


def anchors(path):
    seen, out = {}, set()
    inside = False
    for line in _read(path).splitlines():
        if _FENCE.match(line):
            inside = not inside
            continue
        m = None if inside else _HEADING.match(line)
        if m:
            slug = _slug(m.group(1))
            n = seen.get(slug, 0)
            seen[slug] = n + 1
            out.add(slug if n == 0 else f'{slug}-{n}')
    return out


def links(path):
    for line in _prose_lines(_read(path)):
        for m in _INLINE_LINK.finditer(line):
            yield m.group(1)
        m = _REF_DEF.match(line)
        if m:
            yield m.group(1)


def test_every_relative_link_resolves():
    broken = []
    for md in markdown_files():
        for target in links(md):
            if not target or _SCHEME.match(target):
                continue                                   # http:, https:, mailto: ...
            path, _, fragment = target.partition('#')
            dest = md if not path else os.path.normpath(os.path.join(os.path.dirname(md), path))
            where = f'{_rel(md)}: ({target})'
            if not dest.startswith(ROOT + os.sep):
                broken.append(f'{where} leaves the repository')
            elif not os.path.exists(dest):
                broken.append(f'{where}: no file {_rel(dest)}')
            elif fragment and dest.endswith('.md') and fragment not in anchors(dest):
                broken.append(f'{where}: no heading #{fragment} in {_rel(dest)}')
    assert not broken, 'broken Markdown links:\n' + '\n'.join(broken)


def test_the_link_check_sees_links():
    """Guard against a regex that silently matches nothing: the README links the docs."""
    targets = set(links(README))
    assert 'docs/index.md' in targets and 'docs/parameters.md' in targets, targets


def test_index_lists_every_page():
    index = os.path.join(ROOT, 'docs', 'index.md')
    linked = {os.path.normpath(os.path.join(os.path.dirname(index), t.partition('#')[0]))
              for t in links(index)}
    pages = set(markdown_files()[1:]) - {index}
    missing = sorted(_rel(p) for p in pages - linked)
    assert not missing, f'docs/index.md does not link: {", ".join(missing)}'


# ------------------------------------------------------------------ (c) README

def test_readme_is_short_and_keeps_the_two_commands():
    text = _read(README)
    lines = text.splitlines()
    assert len(lines) < README_MAX_LINES, (
        f'README.md has {len(lines)} lines (limit {README_MAX_LINES}): move detail to docs/')
    heads = [i for i, line in enumerate(lines) if line.startswith('## ')]
    start = lines.index('## The two commands') if '## The two commands' in lines else None
    assert start is not None, 'README.md lost its section "## The two commands"'
    end = next((i for i in heads if i > start), len(lines))
    section = lines[start:end]
    for command in TWO_COMMANDS:
        assert command in section, (
            f'README.md "The two commands" no longer has the line {command!r} '
            f'(CI and other tools depend on it)')


# ------------------------------------------------------------------ (d) every parameter

def documented_parameters():
    """{node: set of parameter names} from the tables of docs/parameters.md."""
    out, node = {}, None
    for line in _read(PARAMS_MD).splitlines():
        if line.startswith('## '):
            node = line[3:].strip()
            out[node] = set()
        m = re.match(r'^\| `([^`]+)` \|', line)
        if m and node is not None:
            out[node].add(m.group(1))
    return out


def test_every_schema_parameter_is_in_parameters_md():
    documented = documented_parameters()
    missing = [f'{node}: {p.name}' for node in node_names() for p in schema_for(node).params
               if p.name not in documented.get(node, set())]
    assert not missing, (f'{len(missing)} parameters missing from docs/parameters.md (regenerate '
                         f'it with {REGENERATE}):\n' + '\n'.join(missing[:20]))
