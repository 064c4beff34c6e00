"""Frozen dataclasses as JAX pytrees that check their values when a user builds them, not when JAX
rebuilds them (equinox's rule: unflattening does not call ``__init__``)."""

from __future__ import annotations

import dataclasses

import jax


def static(**kwargs):
    """A dataclass field that is part of the tree structure (hashable; sets shapes or code paths)."""
    return dataclasses.field(metadata=dict(static=True), **kwargs)


def pytree(cls):
    """Makes ``cls`` a frozen dataclass and registers it as a pytree.

    Fields declared with ``static()`` go into the tree structure; every other field is a leaf (or
    a subtree). ``__post_init__`` runs when the class is called (a user building one, or
    ``dataclasses.replace``), never when JAX unflattens it, so zeros, tracers or placeholders from
    a transformation do not meet the input checks.
    """
    cls = dataclasses.dataclass(frozen=True)(cls)
    fields = dataclasses.fields(cls)
    data = tuple(f.name for f in fields if not f.metadata.get("static"))
    meta = tuple(f.name for f in fields if f.metadata.get("static"))

    def flatten_with_keys(obj):
        children = tuple((jax.tree_util.GetAttrKey(n), getattr(obj, n)) for n in data)
        return children, tuple(getattr(obj, n) for n in meta)

    def flatten(obj):
        return tuple(getattr(obj, n) for n in data), tuple(getattr(obj, n) for n in meta)

    def unflatten(aux, children):
        obj = object.__new__(cls)
        for name, value in zip(meta, aux, strict=True):
            object.__setattr__(obj, name, value)
        for name, value in zip(data, children, strict=True):
            object.__setattr__(obj, name, value)
        return obj

    jax.tree_util.register_pytree_with_keys(cls, flatten_with_keys, unflatten, flatten)
    return cls


def set_fields(obj, **values) -> None:
    """Sets fields of a frozen dataclass from its ``__post_init__`` (the checked, converted values)."""
    for name, value in values.items():
        object.__setattr__(obj, name, value)


def unchecked(cls, **values):
    """An instance of a ``pytree`` class holding ``values`` as they are, without ``__post_init__``'s
    checks: for values built inside a transformation or with batch axes (a stack)."""
    obj = object.__new__(cls)
    set_fields(obj, **values)
    return obj
