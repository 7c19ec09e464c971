"""The official VDA 5050 JSON schemas, loaded and compiled once per version.

2.0.0, 2.1.0 and 3.0.0 ship in ``<package>/schemas/<version>/`` (MIT licence of the VDA, see the
LICENSE.txt beside them; the 2.0.0 tag itself carries no licence file, the repository was published
under the MIT licence later, README.md); 3.0.0 from upstream commit ad16956 ("fixed syntax in
schemas": the 3.0.0 tag's order/state/visualization/factsheet/zoneSet files are not valid JSON or have
keys with trailing blanks; that commit changes only that). A version found in
``$VDA5050_SCHEMA_DIR/<version>/`` wins over the shipped copy.
"""
import json
import os

import jsonschema

VERSIONS = ("2.0.0", "2.1.0", "3.0.0")
PACKAGE_SCHEMAS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                               "schemas")


class SchemaUnavailable(RuntimeError):
    """No schema file for this version/topic."""


def schema_dir(version):
    env = os.environ.get("VDA5050_SCHEMA_DIR")
    if env and os.path.isdir(os.path.join(env, version)):
        return os.path.join(env, version)
    return os.path.join(PACKAGE_SCHEMAS, version)


#: Incoming messages of (version, topic) validated with another version's schema. The 2.0.0
#: instantActions.schema requires ``actionName`` where the 2.0.0 text and every other schema
#: (and its own order.schema) say ``actionType``; a correct 2.0.0 master would be refused. Its
#: 2.1.0 successor differs only in that fix and descriptions.
SUBSTITUTES = {("2.0.0", "instantActions"): "2.1.0"}

_cache = {}


def validator(version, topic):
    """A compiled Draft 2020-12 validator for ``topic`` (state, order, instantActions, zoneSet...)."""
    key = (version, topic, os.environ.get("VDA5050_SCHEMA_DIR"))
    if key not in _cache:
        path = os.path.join(schema_dir(SUBSTITUTES.get((version, topic), version)), topic + ".schema")
        if not os.path.isfile(path):
            raise SchemaUnavailable("no VDA 5050 %s schema for %s (looked for %s)" % (topic, version, path))
        with open(path, encoding="utf-8") as f:
            schema = json.load(f)
        # The files declare draft 2020-12 (3.0.0's zoneSet with an http:// URI): use it explicitly.
        _cache[key] = jsonschema.Draft202012Validator(schema)
    return _cache[key]


def errors(version, topic, document):
    """Schema violations of ``document`` as short strings (empty: valid)."""
    return ["%s: %s" % ("/".join(str(p) for p in e.absolute_path) or "<root>", e.message[:200])
            for e in validator(version, topic).iter_errors(document)]
