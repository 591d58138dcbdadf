"""Caller-owned structs with a leading ``struct_size`` (mirrors ``src/ffi/versioned.rs``), and
the one way options reach the library.

Every options struct is filled with the library's defaults by its ``_init`` function (what the
header's ``*_default(p)`` macros do), then the values a caller gave are written over them
through an :class:`OptionTable`: Python name -> C field and the converter that checks the
value. Defaults therefore live in the library only, and each option's default and range are
documented once, on its C field in ``include/topoloc.h``.
"""

from __future__ import annotations

import ctypes
import difflib
import os
from ctypes import POINTER, Structure, c_size_t, c_uint64
from typing import (
    Any,
    Callable,
    Dict,
    Generic,
    Iterator,
    Mapping,
    Optional,
    Sequence,
    Tuple,
    Type,
    TypeVar,
    Union,
)

import numpy as np

from ._convert import _code, _code_name, _path, _real, _text, _u32, _u64
from ._errors import TopolocError, check

S = TypeVar("S", bound=Structure)

#: A struct's ``_init`` function: ``topoloc_status (*)(T *p, size_t size)``.
InitFunction = Callable[[Any, int], int]
#: Checks a Python value of option ``name`` and gives what its C field stores; raises ``error``
#: (the table's typed error) for a value out of range, ``TypeError`` for one of the wrong type.
Convert = Callable[[Any, str, Type[TopolocError]], Any]

# Room the library may fill when asked for its own struct size (see library_struct_size).
_SCRATCH_BYTES = 4096


def scratch_struct(cls: Type[S]) -> Tuple[S, ctypes.Array[c_uint64]]:
    """A zeroed ``cls`` at the start of an oversized buffer; keep the buffer alive with it."""
    buf = (c_uint64 * (max(_SCRATCH_BYTES, ctypes.sizeof(cls)) // 8))()
    return cls.from_buffer(buf), buf


def defaults(cls: Type[S], init: InitFunction) -> S:
    """A ``cls`` filled by the library's ``_init`` function with this struct's own size: the
    library writes at most that many bytes and sets ``struct_size`` to it (what the C header's
    ``*_default(p)`` macros do with ``sizeof *(p)``)."""
    out = cls()
    check(init(ctypes.byref(out), ctypes.sizeof(cls)))
    return out


def library_struct_size(cls: Type[S], init: InitFunction) -> int:
    """The library's own ``sizeof`` of struct ``cls``: its ``_init`` function, offered an
    oversized buffer, writes ``struct_size = min(offered, sizeof)``."""
    tmp, buf = scratch_struct(cls)
    check(init(ctypes.byref(tmp), ctypes.sizeof(buf)))
    return int(ctypes.cast(buf, POINTER(c_size_t))[0])


# ---------------------------------------------------------------------------------------------
# Options: Python name -> C field(s), converter, reader
# ---------------------------------------------------------------------------------------------


class Field:
    """An option held by one C field: ``convert`` checks a Python value and gives what the
    field stores, ``read`` turns a stored value back into the Python value. Its Python
    ``name`` is the field's unless given."""

    def __init__(
        self,
        field: str,
        convert: Convert,
        read: Callable[[Any], Any],
        name: Optional[str] = None,
    ) -> None:
        self.name = name or field
        self.field = field
        self.fields: Tuple[str, ...] = (field,)
        self._convert = convert
        self._read = read

    def store(self, struct: Any, value: Any, error: Type[TopolocError]) -> None:
        """Writes ``value`` into ``struct``."""
        setattr(struct, self.field, self._convert(value, self.name, error))

    def load(self, struct: Any) -> Any:
        """The option's value as ``struct`` holds it."""
        return self._read(getattr(struct, self.field))


def _text_value(stored: Optional[bytes]) -> Optional[str]:
    return stored.decode("utf-8") if stored else None


def _path_value(stored: Optional[bytes]) -> Optional[str]:
    return os.fsdecode(stored) if stored else None


def _flag(value: Any, name: str, error: Type[TopolocError]) -> bool:
    # A str ("false") or a number would turn the option on by its truth: only booleans.
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, got {type(value).__name__}")
    return bool(value)


def _text_field(value: Any, name: str, error: Type[TopolocError]) -> Optional[bytes]:
    return _text(value, name)


def _path_field(value: Any, name: str, error: Type[TopolocError]) -> bytes:
    return _path(value, name)


class FieldKind:
    """Makes the :class:`Field` of an option of one C type: ``kind(field, name=None)``, its
    Python ``name`` the field's unless given."""

    def __init__(self, convert: Convert, read: Callable[[Any], Any]) -> None:
        self._convert = convert
        self._read = read

    def __call__(self, field: str, name: Optional[str] = None) -> Field:
        return Field(field, self._convert, self._read, name)


#: A ``uint32_t`` option.
unsigned = FieldKind(_u32, int)
#: A ``uint64_t`` option.
unsigned64 = FieldKind(_u64, int)
#: A ``float`` or ``double`` option (the library checks NaN, infinities and the range).
real = FieldKind(_real, float)
#: A ``bool`` option (``True``/``False`` or a numpy bool; anything else is a ``TypeError``).
flag = FieldKind(_flag, bool)
#: A C string option (``str`` or UTF-8 ``bytes``; read back ``None`` for NULL or "").
text = FieldKind(_text_field, _text_value)
#: A file path option (``str``, ``bytes`` or ``os.PathLike``; read back as ``str``).
file_path = FieldKind(_path_field, _path_value)


def choice(field: str, codes: Mapping[str, int], name: Optional[str] = None) -> Field:
    """A C enum option given by its name in ``codes`` (or by its code); read back as the name
    (a code without a name, from a newer library, as the int)."""

    def convert(value: Any, option: str, error: Type[TopolocError]) -> int:
        return _code(value, option, codes, error)

    def read(stored: int) -> Union[str, int]:
        return _code_name(int(stored), codes)

    return Field(field, convert, read, name)


def text_list(field: str, name: Optional[str] = None) -> Field:
    """A comma-separated C string option, given as one string or a sequence of strings."""

    def convert(value: Any, option: str, error: Type[TopolocError]) -> Optional[bytes]:
        joined = value if isinstance(value, (str, bytes)) else ",".join(value)
        return _text(joined, option)

    return Field(field, convert, _text_value, name)


class Option:
    """An option over several C fields (e.g. a flag and the values it enables): ``store`` and
    ``load`` given as functions of the struct."""

    def __init__(
        self,
        name: str,
        fields: Sequence[str],
        store: Callable[[Any, Any, Type[TopolocError]], None],
        load: Callable[[Any], Any],
    ) -> None:
        self.name = name
        self.fields = tuple(fields)
        self.store = store
        self.load = load


AnyOption = Union[Field, Option]


class OptionTable(Generic[S]):
    """The options of one C options struct: ``options``, each a Python name with its C
    field(s) and converter, in the order :meth:`read` reports them. :meth:`fill` starts from the
    library's defaults (``init``, the struct's ``_init`` function) and writes the values given;
    a value out of range raises ``error`` naming the option, a value of the wrong type
    ``TypeError``, an unknown name ``TypeError`` (as Python does for an unexpected keyword
    argument) listing the options."""

    def __init__(
        self,
        what: str,
        struct: Type[S],
        init: InitFunction,
        error: Type[TopolocError],
        options: Sequence[AnyOption],
    ) -> None:
        self.what = what
        self.struct = struct
        self.init = init
        self.error = error
        self.options: Dict[str, AnyOption] = {option.name: option for option in options}
        if len(self.options) != len(options):
            raise ValueError(f"{what} options: two options of one name")

    def __iter__(self) -> Iterator[str]:
        return iter(self.options)

    def __contains__(self, name: object) -> bool:
        return name in self.options

    def defaults(self) -> S:
        """The struct as the library's ``_init`` function fills it."""
        return defaults(self.struct, self.init)

    def fill(self, given: Mapping[str, Any]) -> S:
        """The library's defaults with the options in ``given`` written over them (``None``
        values: the default)."""
        unknown = [name for name in given if name not in self.options]
        if unknown:
            raise TypeError(self._unknown_message(unknown))
        out = self.defaults()
        for name, value in given.items():
            if value is not None:
                self.options[name].store(out, value, self.error)
        return out

    def pick(self, arguments: Mapping[str, Any]) -> Dict[str, Any]:
        """The table's options among a call's ``arguments`` (its ``locals()`` on entry)."""
        return {name: arguments[name] for name in self.options if name in arguments}

    def read(self, struct: S) -> Dict[str, Any]:
        """Every option's value as ``struct`` holds it, by Python name."""
        return {name: option.load(struct) for name, option in self.options.items()}

    def default_values(self) -> Dict[str, Any]:
        """Every option's library default, by Python name."""
        return self.read(self.defaults())

    def _unknown_message(self, unknown: Sequence[str]) -> str:
        names = ", ".join(repr(n) for n in unknown)
        hints = [
            f"{n!r} -> {close[0]!r}"
            for n in unknown
            for close in [difflib.get_close_matches(n, self.options, n=1)]
            if close
        ]
        hint = f" (did you mean {', '.join(hints)}?)" if hints else ""
        return (
            f"unexpected {self.what} option(s) {names}{hint}; the options are "
            f"{', '.join(self.options)}"
        )
