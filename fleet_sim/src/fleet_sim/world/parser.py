"""Stage world-file syntax: tokens, includes, ``define`` macros, entities and properties.

The grammar is Stage's worldfile format::

    # comment to the end of the line
    include "relative/path.inc"
    define NAME BASE ( body )          # a macro; BASE is a built-in type or another macro
    name value                          # a property: number, "string" or [ tuple ]
    type ( body )                       # an entity (model); type is a built-in or a macro

A body holds properties and nested entities. Instantiating a macro gives an
entity of the macro's root built-in type whose properties are inherited along
the macro chain (base first, each level overriding) and whose children are the
children of every level followed by the instance's own.

This module knows nothing about what the properties mean (see ``loader``). Every
value remembers the file and line it was written on, so later checks can say
exactly where a bad value is. Syntax errors raise ``WorldSyntaxError`` with file,
line and reason.
"""
import os
import re
from dataclasses import dataclass, field
from typing import List, Tuple, Union

from fleet_sim.errors import WorldSyntaxError

_TOKEN_RE = re.compile(r"""
    (?P<space>[ \t\r\f\v]+)
  | (?P<newline>\n)
  | (?P<comment>\#[^\n]*)
  | (?P<string>"[^"\n]*")
  | (?P<badstring>"[^"\n]*)
  | (?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![A-Za-z_\[]))
  | (?P<word>[A-Za-z_][A-Za-z0-9_.:\-]*(?:\[\d+\])?)
  | (?P<punct>[()\[\]])
""", re.VERBOSE)


@dataclass(frozen=True)
class Token:
    kind: str          # 'string', 'number', 'word', '(' , ')', '[', ']', 'eof'
    text: str
    line: int


def tokenize(text, path):
    """Splits world-file text into tokens; an unknown character is a syntax error."""
    tokens = []
    line = 1
    pos = 0
    while pos < len(text):
        m = _TOKEN_RE.match(text, pos)
        if m is None:
            raise WorldSyntaxError(path, line, "unexpected character %r" % text[pos])
        kind = m.lastgroup
        if kind == "newline":
            line += 1
        elif kind == "badstring":
            raise WorldSyntaxError(path, line, "unterminated string %s" % m.group()[:40])
        elif kind == "punct":
            tokens.append(Token(m.group(), m.group(), line))
        elif kind in ("string", "number", "word"):
            tokens.append(Token(kind, m.group(), line))
        pos = m.end()
    tokens.append(Token("eof", "", line))
    return tokens


Scalar = Union[float, str]


@dataclass(frozen=True)
class Property:
    """One ``name value`` line; ``value`` is a float, a str or a tuple of those."""
    name: str
    value: Union[Scalar, Tuple[Scalar, ...]]
    path: str
    line: int

    def where(self):
        return "%s:%d" % (self.path, self.line)


@dataclass
class EntityDecl:
    """``type ( body )`` as written (before macro expansion)."""
    type: str
    body: list
    path: str
    line: int


@dataclass
class MacroDecl:
    """``define name base ( body )``."""
    name: str
    base: str
    body: list
    path: str
    line: int


@dataclass
class Entity:
    """An entity after macro expansion.

    ``type`` is the built-in root type (model, position, ranger, ...), ``kind``
    the name used at the instantiation (e.g. ``pr2``), ``chain`` the macro names
    from the instance down to the built-in.
    """
    type: str
    kind: str
    chain: List[str]
    props: dict            # name -> Property (the winning one)
    children: List["Entity"]
    path: str
    line: int

    def where(self):
        return "%s:%d" % (self.path, self.line)


@dataclass
class ParsedWorld:
    """The top level of a world file after includes and macro expansion."""
    path: str
    props: dict = field(default_factory=dict)
    entities: List[Entity] = field(default_factory=list)
    files: List[str] = field(default_factory=list)   # every file read, in order


class _Parser:
    def __init__(self, tokens, path):
        self.tokens = tokens
        self.path = path
        self.i = 0

    def peek(self, k=0):
        return self.tokens[min(self.i + k, len(self.tokens) - 1)]

    def take(self):
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def error(self, tok, reason):
        raise WorldSyntaxError(self.path, tok.line, reason)

    def expect(self, kind, what):
        tok = self.take()
        if tok.kind != kind:
            self.error(tok, "expected %s, found %s" % (what, _describe(tok)))
        return tok

    def parse_file(self):
        items = self.parse_body(top=True)
        return items

    def parse_body(self, top):
        items = []
        while True:
            tok = self.peek()
            if tok.kind == "eof":
                if not top:
                    self.error(tok, "missing ')': end of file inside a block")
                return items
            if tok.kind == ")":
                if top:
                    self.error(tok, "unbalanced ')'")
                return items
            if tok.kind != "word":
                self.error(tok, "expected a property or model name, found %s" % _describe(tok))
            self.take()
            if tok.text == "include":
                if not top:
                    self.error(tok, "include is only allowed at the top level")
                name = self.expect("string", "a quoted file name after include")
                items.append(("include", name.text[1:-1], tok.line))
            elif tok.text == "define":
                if not top:
                    self.error(tok, "define is only allowed at the top level")
                name = self.expect("word", "a macro name after define")
                base = self.expect("word", "a base type after 'define %s'" % name.text)
                self.expect("(", "'(' to open the body of macro %s" % name.text)
                body = self.parse_body(top=False)
                self.expect(")", "')' to close macro %s" % name.text)
                items.append(MacroDecl(name.text, base.text, body, self.path, tok.line))
            elif self.peek().kind == "(":
                self.take()
                body = self.parse_body(top=False)
                self.expect(")", "')' to close %s" % tok.text)
                items.append(EntityDecl(tok.text, body, self.path, tok.line))
            else:
                items.append(Property(tok.text, self.parse_value(tok), self.path, tok.line))

    def parse_value(self, name_tok):
        tok = self.take()
        if tok.kind == "number":
            return float(tok.text)
        if tok.kind == "string":
            return tok.text[1:-1]
        if tok.kind == "[":
            values = []
            while True:
                t = self.take()
                if t.kind == "]":
                    return tuple(values)
                if t.kind == "number":
                    values.append(float(t.text))
                elif t.kind == "string":
                    values.append(t.text[1:-1])
                else:
                    self.error(t, "in the value of '%s': expected a number, a string or ']', found %s"
                               % (name_tok.text, _describe(t)))
        self.error(tok, "property '%s' needs a value (number, \"string\" or [tuple]), found %s"
                   % (name_tok.text, _describe(tok)))


def _describe(tok):
    if tok.kind == "eof":
        return "end of file"
    return "%s %r" % (tok.kind if tok.kind in ("word", "number", "string") else "symbol", tok.text)


# Built-in Stage entity types. Anything else must be a macro.
BUILTIN_TYPES = frozenset([
    "model", "position", "ranger", "sensor", "laser", "block", "window", "blobfinder",
    "fiducial", "camera", "gripper", "actuator", "lightindicator", "blinkenlight",
    "bumper", "ptz", "power", "speech", "wifi", "sonar", "fiducialfinder",
])

_MAX_INCLUDE_DEPTH = 32
_MAX_MACRO_DEPTH = 64


def parse_world(path, log=None):
    """Reads a world file with its includes and expands its macros.

    Returns a ``ParsedWorld``; raises ``WorldSyntaxError`` (file, line, reason)
    for a malformed file, a missing include or an undefined/recursive macro.
    ``log(level, message)`` receives debug and warning lines.
    """
    log = log or (lambda level, msg: None)
    path = os.path.abspath(path)
    result = ParsedWorld(path=path)
    macros = {}
    top_items = []
    _read_file(path, None, 0, [], result, macros, top_items)
    for item in top_items:
        if isinstance(item, Property):
            result.props[item.name] = item
        else:
            result.entities.append(_expand(item, macros, log))
    return result


def _read_file(path, from_where, depth, stack, result, macros, top_items):
    if depth > _MAX_INCLUDE_DEPTH or path in stack:
        f, line = from_where
        raise WorldSyntaxError(f, line, "include loop: %s includes itself via %s"
                               % (path, " -> ".join(stack)))
    try:
        with open(path, "r", encoding="utf-8", errors="replace") as handle:
            text = handle.read()
    except OSError as err:
        if from_where is None:
            raise WorldSyntaxError(path, 0, "cannot read world file (%s)" % err.strerror) from err
        f, line = from_where
        raise WorldSyntaxError(f, line, "cannot read included file %s (%s)" % (path, err.strerror)) from err
    result.files.append(path)
    items = _Parser(tokenize(text, path), path).parse_file()
    for item in items:
        if isinstance(item, tuple):          # include
            _, name, line = item
            inc = os.path.normpath(os.path.join(os.path.dirname(path), name))
            _read_file(inc, (path, line), depth + 1, stack + [path], result, macros, top_items)
        elif isinstance(item, MacroDecl):
            macros[item.name] = item         # a later define replaces an earlier one, as in Stage
        else:
            top_items.append(item)


def _expand(decl, macros, log, depth=0):
    """EntityDecl -> Entity, resolving the macro chain of its type."""
    chain = []
    levels = []                        # bodies from the built-in upwards
    t = decl.type
    seen = set()
    while True:
        macro = macros.get(t)
        if macro is not None and t not in seen:
            # a macro may shadow a built-in name (the Willow world has 'define block model')
            if len(chain) > _MAX_MACRO_DEPTH:
                raise WorldSyntaxError(macro.path, macro.line, "macro chain of '%s' too deep" % t)
            seen.add(t)
            chain.append(t)
            levels.append(macro.body)
            t = macro.base
        elif t in BUILTIN_TYPES:
            break
        elif t in seen:
            raise WorldSyntaxError(macros[t].path, macros[t].line,
                                   "macro '%s' is defined in terms of itself" % t)
        else:
            raise WorldSyntaxError(decl.path, decl.line,
                                   "unknown model type '%s' (not a Stage type and not defined "
                                   "with 'define')" % t)
    levels.reverse()
    levels.append(decl.body)
    props = {}
    children = []
    for body in levels:
        for item in body:
            if isinstance(item, Property):
                props[item.name] = item
            elif isinstance(item, EntityDecl):
                if depth > _MAX_MACRO_DEPTH:
                    raise WorldSyntaxError(item.path, item.line, "models nested too deeply")
                children.append(_expand(item, macros, log, depth + 1))
    return Entity(type=t, kind=decl.type, chain=chain, props=props, children=children,
                  path=decl.path, line=decl.line)

