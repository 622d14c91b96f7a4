"""The rosbags typestore of vd: standard ROS 2 types plus vd_msgs, and CDR helpers.

Base store: ``Stores.ROS2_JAZZY``. Jazzy is the oldest distribution we support; the types we
use (std_msgs, geometry_msgs, rosgraph_msgs, diagnostic_msgs, builtin_interfaces) have the
same definitions and RIHS01 hashes in Jazzy and Kilted, so bags are valid for both.

vd_msgs are registered from their ``.msg`` files: the installed share directory (found with
``ament_index_python``) when the package is installed, else the source tree next to this
package (tests, uninstalled checkouts).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import pickle
from pathlib import Path
from typing import Any, Final

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from vd_observer_node.bag.errors import BagFormatError, UnknownMessageTypeError

__all__ = [
    'BASE_STORE',
    'COMMON_TYPES',
    'VD_MSG_TYPES',
    'decoding_type',
    'deserialize',
    'find_vd_msgs_dir',
    'kept_types',
    'message_class',
    'message_definition',
    'parsed_vd_msgs',
    'register_definition',
    'serialize',
    'store_with',
    'type_hash',
    'vd_typestore',
]

BASE_STORE = Stores.ROS2_JAZZY
#: bytes after a message's last field that `deserialize` accepts (alignment padding)
_MAX_TAIL = 8

VD_MSG_TYPES = (
    'vd_msgs/msg/Estimates',
    'vd_msgs/msg/Friction',
    'vd_msgs/msg/MassEstimate',
    'vd_msgs/msg/Resistances',
    'vd_msgs/msg/RollingRadiusEstimate',
    'vd_msgs/msg/Slope',
    'vd_msgs/msg/TireForces',
    'vd_msgs/msg/TorqueOffsetEstimate',
    'vd_msgs/msg/WheelAngles',
    'vd_msgs/msg/WheelStates',
    'vd_msgs/msg/WheelTorques',
)


def find_vd_msgs_dir() -> Path:
    """Locate the folder holding vd_msgs' ``*.msg`` files.

    Returns:
        The installed ``share/vd_msgs/msg`` if vd_msgs is installed, else ``src/vd_msgs/msg``
        of the source tree this module lives in.

    Raises:
        UnknownMessageTypeError: neither location exists.
    """
    try:
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )

        try:
            installed = Path(get_package_share_directory('vd_msgs')) / 'msg'
            if installed.is_dir():
                return installed
        except (PackageNotFoundError, ValueError, LookupError, OSError):
            # OSError: AMENT_PREFIX_PATH unset (no ROS environment sourced)
            pass
    except ImportError:  # ament_index_python is optional for the ROS-free core
        pass
    # .../src/vd_observer_node/vd_observer_node/bag/typestore.py -> .../src/vd_msgs/msg
    source = Path(__file__).resolve().parents[3] / 'vd_msgs' / 'msg'
    if source.is_dir():
        return source
    raise UnknownMessageTypeError(
        f'vd_msgs message files not found (not installed, and no {source})'
    )


#: the standard types vd reads and writes itself (its sensors, the mapped inputs' types, the
#: clock, the diagnostics); with vd_msgs and what they are made of, the store of a start
#: holds these (`vd_typestore`), and takes the rest of Jazzy's when another is asked for
COMMON_TYPES: Final = (
    'diagnostic_msgs/msg/DiagnosticArray',
    'geometry_msgs/msg/AccelStamped',
    'geometry_msgs/msg/PoseStamped',
    'geometry_msgs/msg/TwistStamped',
    'nav_msgs/msg/Odometry',
    'rosgraph_msgs/msg/Clock',
    'sensor_msgs/msg/Imu',
    'sensor_msgs/msg/JointState',
    'sensor_msgs/msg/NavSatFix',
    'std_msgs/msg/Float64MultiArray',
)
_CACHE_DIR: Final = Path(__file__).parent / '__pycache__'


@functools.cache
def vd_typestore() -> Typestore:
    """The shared typestore: ROS 2 Jazzy standard types + vd_msgs (built once).

    At a start it holds vd_msgs and :data:`COMMON_TYPES` with what they are made of, read
    from the definitions kept beside the bytecode (`kept_types`; importing rosbags' six
    stores of ROS distributions took 0.06 s of every start); `store_with` adds the rest of
    Jazzy's types the first time one of them is asked for.
    """
    kept = kept_types(find_vd_msgs_dir(), _CACHE_DIR)
    store = get_typestore(Stores.EMPTY)
    store.register({k: v for k, v in kept.items() if k not in store.fielddefs})
    return store


def store_with(msgtype: str) -> Typestore:
    """The shared typestore, with every Jazzy type in it (`_whole_store`) if ``msgtype`` is
    not among those of a start."""
    store = vd_typestore()
    return store if msgtype in store.fielddefs else _whole_store()


@functools.cache
def _whole_store() -> Typestore:
    """The shared typestore with the rest of Jazzy's types added (once): a foreign bag's
    definitions are then registered only where Jazzy has none, as always."""
    store = vd_typestore()
    full = get_typestore(BASE_STORE)
    store.register({k: v for k, v in full.fielddefs.items() if k not in store.fielddefs})
    return store


def kept_types(folder: Path, cache_dir: Path) -> dict[str, Any]:
    """vd_msgs (`parsed_vd_msgs`) and :data:`COMMON_TYPES` with every type they are made
    of, as rosbags' Jazzy store defines them; kept in ``cache_dir`` under a digest of the
    rosbags stores' files and vd_msgs' text, read back while both are unchanged."""
    import rosbags.typesys.stores

    vd_types = parsed_vd_msgs(folder, cache_dir)
    digest = hashlib.sha256(repr(sorted(vd_types.items())).encode())
    for path in sorted(Path(str(rosbags.typesys.stores.__file__)).parent.glob('*.py')):
        digest.update(path.read_bytes())
    cache = cache_dir / f'vd_store_types.{digest.hexdigest()[:20]}.pickle'
    kept = _kept(cache)
    if kept is not None:
        return kept
    full = get_typestore(BASE_STORE)
    full.register(vd_types)
    wanted, types = [*vd_types, *COMMON_TYPES], {}
    while wanted:  # the types named and every type their fields name
        name = wanted.pop()
        if name in types or name not in full.fielddefs:
            continue
        types[name] = full.fielddefs[name]
        wanted.extend(t for t in full.fielddefs if t in repr(types[name]))
    _keep(cache, 'vd_store_types', types)
    return types


def _parser_digest() -> bytes:
    """The bytes of rosbags' message parser and of the node types it builds: what, besides
    the text, the parsed definitions depend on."""
    import rosbags.interfaces
    import rosbags.typesys.msg

    digest = hashlib.sha256()
    for module in (rosbags.typesys.msg, rosbags.interfaces):
        digest.update(Path(str(module.__file__)).read_bytes())
    return digest.digest()


def parsed_vd_msgs(folder: Path, cache_dir: Path) -> dict[str, Any]:
    """vd_msgs' definitions parsed by rosbags (`get_types_from_msg`), kept in ``cache_dir``.

    rosbags' parser takes 0.1 s for vd_msgs' files, a tenth of a short `vd replay`'s start
    and of every node's. The parsed definitions are kept under a name that digests the files'
    text and rosbags' parser, and read back (1 ms) while both are unchanged; anything else (a
    changed file, another rosbags, an unreadable or read-only cache) parses them anew.

    Args:
        folder: the ``*.msg`` files (`find_vd_msgs_dir`).
        cache_dir: where the parsed definitions are kept (created if absent).

    Returns:
        The types as rosbags' ``Typestore.register`` takes them.
    """
    texts = [(p.stem, p.read_text(encoding='utf-8')) for p in sorted(folder.glob('*.msg'))]
    digest = hashlib.sha256(_parser_digest())
    digest.update(repr(texts).encode())
    cache = cache_dir / f'vd_msgs_types.{digest.hexdigest()[:20]}.pickle'
    kept = _kept(cache)
    if kept is not None:
        return kept
    types: dict[str, Any] = {}
    for stem, text in texts:
        types.update(get_types_from_msg(text, f'vd_msgs/msg/{stem}'))
    _keep(cache, 'vd_msgs_types', types)
    return types


def _kept(cache: Path) -> dict[str, Any] | None:
    """The types `_keep` wrote to ``cache`` (None: absent, unreadable, or not what was
    written: to be built anew)."""
    try:
        with cache.open('rb') as f:
            kept = pickle.load(f)
    except Exception:
        return None
    return kept if isinstance(kept, dict) else None


def _keep(cache: Path, stem: str, types: dict[str, Any]) -> None:
    """Write ``types`` to ``cache`` in place of the other ``stem.*.pickle`` (stale); a folder
    that cannot be written (a read-only install) is left as it is."""
    partial = cache.with_name(f'{cache.name}.{os.getpid()}')
    try:
        cache.parent.mkdir(exist_ok=True)
        for stale in cache.parent.glob(f'{stem}.*.pickle'):
            stale.unlink(missing_ok=True)
        partial.write_bytes(pickle.dumps(types))
        os.replace(partial, cache)  # whole or not at all for a process reading it
    except OSError:
        with contextlib.suppress(OSError):
            partial.unlink(missing_ok=True)


def _require(msgtype: str) -> Typestore:
    store = store_with(msgtype)
    if msgtype not in store.fielddefs:
        raise UnknownMessageTypeError(f'unknown message type {msgtype!r}')
    return store


def register_definition(msgtype: str, definition: str) -> None:
    """Register a type from a ``ros2msg`` definition embedded in a bag (with dependencies).

    Types the store already knows are kept, so a foreign bag cannot redefine std types.

    Raises:
        UnknownMessageTypeError: the definition does not parse.
    """
    store = store_with(msgtype)
    if msgtype in store.fielddefs:
        return
    try:
        types = get_types_from_msg(definition, msgtype)
    except Exception as exc:  # rosbags raises several parser exception types
        raise UnknownMessageTypeError(f'cannot parse definition of {msgtype!r}: {exc}') from exc
    store.register({k: v for k, v in types.items() if k not in store.fielddefs})


@functools.cache
def decoding_type(msgtype: str, definition: str) -> str:
    """The type to decode a bag topic's messages with, given the definition the bag embeds.

    A bag keeps the definition its messages were written with. When that differs from the
    vd typestore's (a bag recorded before a field was added to a vd_msgs type, such as
    ``torque_source`` in TireForces, Friction and Slope), the bag's definition is registered
    under an alias, ``<package>_legacy_<digest>/msg/<Type>``, and the alias is returned:
    decoding with it reads the old layout (the fields the old type lacks are absent).

    Args:
        msgtype: the bag's type name, e.g. 'vd_msgs/msg/Slope'.
        definition: the bag's ``ros2msg`` definition of it ('' if none).

    Returns:
        ``msgtype`` itself when the fields agree, the definition is empty, or the type is
        unknown to the typestore (then `register_definition` registers it as it is).

    Raises:
        UnknownMessageTypeError: the definition does not parse.
    """
    store = store_with(msgtype)
    if not definition or msgtype not in store.fielddefs:
        return msgtype
    try:
        types = get_types_from_msg(definition, msgtype)
    except Exception as exc:  # rosbags raises several parser exception types
        raise UnknownMessageTypeError(f'cannot parse definition of {msgtype!r}: {exc}') from exc
    if msgtype not in types or types[msgtype][1] == store.fielddefs[msgtype][1]:
        return msgtype
    package, _, name = msgtype.split('/')
    digest = hashlib.sha256(definition.encode()).hexdigest()[:12]
    alias = f'{package}_legacy_{digest}/msg/{name}'
    if alias not in store.fielddefs:
        store = _whole_store()  # the bag's dependencies where Jazzy has none, as always
        extra = {k: v for k, v in types.items() if k != msgtype and k not in store.fielddefs}
        store.register({**extra, alias: types[msgtype]})
    return alias


def message_class(msgtype: str) -> Any:
    """The rosbags dataclass of ``msgtype`` (e.g. to build messages to serialize)."""
    return _require(msgtype).types[msgtype]


def serialize(msg: Any, msgtype: str | None = None) -> bytes:
    """Serialize a rosbags message object to CDR (little endian, with encapsulation header)."""
    name = msgtype or str(msg.__msgtype__)
    return bytes(_require(name).serialize_cdr(msg, name))


def deserialize(data: bytes | memoryview, msgtype: str) -> Any:
    """Deserialize CDR bytes of ``msgtype`` to a rosbags message object.

    Raises:
        UnknownMessageTypeError: the type is not known.
        BagFormatError: the bytes do not decode as that type.
    """
    store = _require(msgtype)
    raw = bytes(data)
    try:
        if len(raw) < 4 or raw[:2] not in (b'\x00\x00', b'\x00\x01'):
            raise ValueError('not a CDR encapsulation')
        # What rosbags' deserialize_cdr does, with one difference: rclpy's Fast CDR may end
        # a message with up to 8 bytes past its last field (after a JointState's empty
        # effort array), where rosbags refuses more than 3.
        msgdef = store.get_msgdef(msgtype)
        decode = msgdef.deserialize_cdr_le if raw[1] else msgdef.deserialize_cdr_be
        message, pos = decode(raw[4:], 0, msgdef.cls, store)
    except Exception as exc:  # rosbags raises struct/index/assertion errors on bad bytes
        raise BagFormatError(f'cannot decode a {msgtype} message: {exc}') from exc
    if len(raw) - 4 - pos > _MAX_TAIL:
        raise BagFormatError(
            f'cannot decode a {msgtype} message: {len(raw) - 4 - pos} bytes after its fields'
        )
    return message


@functools.cache
def message_definition(msgtype: str) -> str:
    """Full ROS 2 message definition with dependencies (``ros2msg`` schema encoding).

    This is the text rosbag2 embeds in MCAP schema records: the type's fields, then for every
    dependency a ``====`` separator line and ``MSG: pkg/Type`` followed by its fields.
    """
    text, _ = _require(msgtype).generate_msgdef(msgtype, ros_version=2)
    return str(text)


@functools.cache
def type_hash(msgtype: str) -> str:
    """RIHS01 type description hash, as rosbag2 (Iron+) stores it in topic metadata."""
    return str(_require(msgtype).hash_rihs01(msgtype))
