"""
The one YAML reader of the package: safe, YAML 1.2 floats, and bounded.

:func:`loads` and :func:`load_file` refuse, with the caller's ``error=`` class (:class:`YamlError`
by default) naming the file or field and the limit, what exceeds :data:`MAX_BYTES`,
:data:`MAX_DEPTH`, :data:`MAX_ALIASES`, :data:`MAX_NODES` or :data:`MAX_INT_DIGITS`, non-UTF-8
bytes, a recursive alias or a duplicate key (docs/scenes.md#limits).
"""

import os
from pathlib import Path
import re
import stat

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.nodes import MappingNode, ScalarNode, SequenceNode
from yaml.resolver import Resolver

try:  # libyaml scans and parses (7x faster); composing stays here, with the limits
    from yaml.cyaml import CParser as _CParser
except ImportError:  # PyYAML without libyaml: the pure-Python reader, scanner and parser
    _CParser = None

MAX_BYTES = 1 << 20
"""Largest YAML document read, in bytes (1 MiB; the built-in scenes are below 20 kB)."""
MAX_DEPTH = 64
"""Deepest nesting of mappings and sequences, counted through aliases (scenes use 5)."""
MAX_NODES = 100_000
"""Most nodes of a document with every alias expanded (scenes have a few hundred)."""
MAX_ALIASES = 1_000
"""Most aliases (``*name``) in one document."""
MAX_INT_DIGITS = 32
"""Longest integer literal, in characters (scene integers have a few digits)."""

_MERGE_TAG = 'tag:yaml.org,2002:merge'
_FLOAT_12 = re.compile(r'^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$')


class YamlError(ValueError):
    """A YAML text cannot be read: not a file, not UTF-8, not YAML, or over a limit."""


class _Refused(Exception):
    """Raised inside the loader; turned into the caller's error class by :func:`loads`."""


if _CParser is not None:
    class _Base(Composer, _CParser, SafeConstructor, Resolver):
        """PyYAML's safe loader with libyaml's parser and the pure-Python composer."""

        def __init__(self, stream):
            _CParser.__init__(self, stream)
            SafeConstructor.__init__(self)
            Resolver.__init__(self)
            Composer.__init__(self)
else:
    _Base = yaml.SafeLoader


class Loader(_Base):
    """A safe loader: YAML 1.2 floats, duplicate keys refused, the limits (use :func:`loads`)."""

    label = 'YAML'

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._aliases = 0
        self._extent = {}       # id(node) -> (expanded node count, expanded depth)
        self._paths = {}        # id(mapping node) -> its field path ('links.crank')
        self._path = []

    def compose_document(self):
        """Compose one document; the bookkeeping of its anchors ends with it."""
        node = super().compose_document()
        self._extent.clear()
        return node

    def compose_node(self, parent, index):
        """Compose a node, counting its expanded size and depth (aliases included)."""
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            target = self.anchors.get(event.anchor)
            if target is not None:
                self._aliases += 1
                if self._aliases > MAX_ALIASES:
                    self._refuse(f'more than {MAX_ALIASES} aliases (a fixed limit)',
                                 event.start_mark)
                if id(target) not in self._extent:
                    self._refuse(f'alias *{event.anchor} refers to a node that contains it '
                                 '(a recursive alias)', event.start_mark)
            return super().compose_node(parent, index)
        self._depth += 1
        if self._depth > MAX_DEPTH:
            self._refuse(f'nesting deeper than {MAX_DEPTH} levels (a fixed limit)',
                         self.peek_event().start_mark)
        self._path.append(_segment(parent, index))
        try:
            node = super().compose_node(parent, index)
        finally:
            self._path.pop()
            self._depth -= 1
        if isinstance(node, MappingNode):
            self._paths[id(node)] = _join(self._path + [_segment(parent, index)])
            children = [n for pair in node.value for n in pair]
        elif isinstance(node, SequenceNode):
            children = node.value
        else:
            children = ()
        count, depth = 1, 0
        for child in children:
            c_count, c_depth = self._extent[id(child)]
            count += c_count
            depth = max(depth, c_depth)
        depth += not isinstance(node, ScalarNode)
        if depth > MAX_DEPTH:
            self._refuse(f'nesting deeper than {MAX_DEPTH} levels through aliases '
                         '(a fixed limit)', node.start_mark)
        if count > MAX_NODES:
            self._refuse(f'more than {MAX_NODES} nodes with its aliases expanded '
                         '(a fixed limit; a "billion laughs" document?)', node.start_mark)
        self._extent[id(node)] = (count, depth)
        return node

    def construct_mapping(self, node, deep=False):
        """Construct a mapping; a key given twice is refused naming its path and lines."""
        if isinstance(node, MappingNode):
            first = {}
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:
                    continue  # merged keys may be overridden: that is what merging is for
                key = self.construct_object(key_node, deep=True)
                try:
                    earlier = first.setdefault(key, key_node)
                except TypeError:
                    continue  # unhashable: PyYAML's own error names it below
                if earlier is not key_node:
                    where = _join([self._paths.get(id(node), ''), str(key)])
                    raise _Refused(
                        f'{where}: duplicate key in {self.label} at line '
                        f'{key_node.start_mark.line + 1} (first at line '
                        f'{earlier.start_mark.line + 1}); expected each key once per mapping '
                        '(the later value would silently win)')
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node):
        """Construct an integer of at most :data:`MAX_INT_DIGITS` characters."""
        text = self.construct_scalar(node)
        if len(text.replace('_', '').lstrip('+-')) > MAX_INT_DIGITS:
            self._refuse(f'an integer of {len(text)} characters, expected at most '
                         f'{MAX_INT_DIGITS} (a fixed limit)', node.start_mark)
        return super().construct_yaml_int(node)

    def _refuse(self, what, mark):
        raise _Refused(f'{self.label}: {what}{_at(mark)}')


Loader.add_implicit_resolver('tag:yaml.org,2002:float', _FLOAT_12, list('-+0123456789'))
Loader.add_constructor('tag:yaml.org,2002:int', Loader.construct_yaml_int)


def _segment(parent, index):
    if isinstance(parent, MappingNode) and isinstance(index, ScalarNode):
        return index.value
    if isinstance(parent, SequenceNode) and isinstance(index, int):
        return f'[{index}]'
    return ''


def _join(parts):
    out = ''
    for p in parts:
        if not p:
            continue
        out += p if p.startswith('[') or not out else f'.{p}'
    return out


def _at(mark):
    return '' if mark is None else f' at line {mark.line + 1}, column {mark.column + 1}'


def loads(text, label='YAML', error=YamlError):
    """
    Return the Python value of one YAML document ``text`` (``None`` if empty), or raise ``error``.

    ``label`` names the text in errors (``scene hoeken.yaml``, ``balance.mass_bounds``).
    """
    if not isinstance(text, str):
        raise error(f'{label}: got {type(text).__name__}, expected YAML text')
    if len(text) > MAX_BYTES or len(text.encode('utf-8', 'surrogatepass')) > MAX_BYTES:
        raise error(f'{label}: got more than {MAX_BYTES} bytes of YAML, expected at most '
                    f'{MAX_BYTES} (a fixed limit)')
    loader = None
    try:
        loader = Loader(text)  # its reader refuses control characters at once
        loader.label = label
        return loader.get_single_data()
    except _Refused as exc:
        raise error(str(exc)) from None
    except yaml.YAMLError as exc:
        raise error(f'{label}: {_syntax_error(text, exc)}') from None
    except RecursionError:  # cannot happen below MAX_DEPTH; never let it escape
        raise error(f'{label}: nesting too deep to read, expected at most {MAX_DEPTH} levels '
                    '(a fixed limit)') from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. a timestamp 2001-02-30
        raise error(f'{label}: a value cannot be read ({exc})') from None
    finally:
        if loader is not None:
            loader.dispose()


def _syntax_error(text, exc):
    """Return 'not valid YAML at line L, column C: PROBLEM' (PyYAML's Python parser's message)."""
    if _CParser is not None and not isinstance(exc, yaml.composer.ComposerError):
        try:
            for _ in yaml.parse(text, Loader=yaml.SafeLoader):
                pass
        except yaml.YAMLError as python_exc:
            return _describe(python_exc, text)
        except RecursionError:  # the Python parser is not recursive: defensive only
            pass
        return _describe(exc, text.encode('utf-8', 'surrogatepass'))
    return _describe(exc, text)


def _describe(exc, where):
    if isinstance(exc, yaml.reader.ReaderError):
        newline = '\n' if isinstance(where, str) else b'\n'  # libyaml counts bytes
        line = where.count(newline, 0, exc.position) + 1
        column = exc.position - (where.rfind(newline, 0, exc.position) + 1) + 1
        return (f'not valid YAML at line {line}, column {column}: character '
                f'#x{exc.character:04x} (a control character) is not allowed')
    mark = getattr(exc, 'problem_mark', None) or getattr(exc, 'context_mark', None)
    reason = getattr(exc, 'problem', None) or ' '.join(str(exc).split())
    return f'not valid YAML{_at(mark)}: {reason}'


def check_file(path, label, error=YamlError):
    """
    Return ``path`` as a ``Path`` if it is a non-empty regular file of at most MAX_BYTES.

    Otherwise raise ``error`` saying what it is (missing, a directory, a device, empty, large).
    """
    path = Path(path).expanduser()
    text = str(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise error(f'{label}: file {text!r} does not exist') from None
    except OSError as exc:
        raise error(f'{label}: file {text!r} cannot be read ({exc.strerror})') from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f'{label}: {text!r} is a directory, expected a YAML file')
    if not stat.S_ISREG(info.st_mode):
        raise error(f'{label}: {text!r} is not a regular file (a device or pipe), expected '
                    'a YAML file')
    if info.st_size == 0:
        raise error(f'{label}: file {text!r} is empty, expected a YAML mapping')
    if info.st_size > MAX_BYTES:
        raise error(f'{label}: file {text!r} has {info.st_size} bytes, expected at most '
                    f'{MAX_BYTES} (a fixed limit)')
    return path


def decode(data, label, error=YamlError):
    """Return UTF-8 ``data`` (bytes) as text, or raise ``error`` naming the first bad byte."""
    try:
        return data.decode('utf-8-sig')
    except UnicodeDecodeError as exc:
        line = data.count(b'\n', 0, exc.start) + 1
        column = exc.start - (data.rfind(b'\n', 0, exc.start) + 1) + 1
        raise error(f'{label}: byte 0x{data[exc.start]:02x} at offset {exc.start} (line '
                    f'{line}, column {column}) is not UTF-8; expected a UTF-8 text file '
                    '(re-save it as UTF-8)') from None


def load_file(path, label=None, error=YamlError):
    """Return the parsed YAML of file ``path`` (:func:`check_file`; ``label`` in errors)."""
    label = label or f'file {str(path)!r}'
    path = check_file(path, label, error)
    try:
        with open(path, 'rb') as f:
            data = f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise error(f'{label}: cannot be read ({exc.strerror})') from None
    if len(data) > MAX_BYTES:
        raise error(f'{label}: has more than {MAX_BYTES} bytes, expected at most {MAX_BYTES} '
                    '(a fixed limit)')
    return loads(decode(data, label, error), label, error)
