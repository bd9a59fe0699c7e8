"""How close two names are as a typing slip: the test both the unit hints (``units.py``) and the
misspelt-term notes (``vocabulary.py``) use."""

from __future__ import annotations

__all__ = ["one_edit_apart"]


def one_edit_apart(a: str, b: str, *, replaced: bool = True) -> bool:
    """One letter replaced, added, dropped, or two neighbours swapped (``Fam``, ``Fna`` for ``Fan``,
    ``DEG_CC`` for ``DEG_C``), which a similarity ratio on short names does not reach; ``replaced``
    False: not one letter replaced (in unit names it is often another scale: ``DEG_K``, ``DEG_F``)."""
    if abs(len(a) - len(b)) > 1 or a == b:
        return False
    if len(a) == len(b):
        differ = [i for i, (x, y) in enumerate(zip(a, b)) if x != y]
        return (replaced and len(differ) == 1) or (len(differ) == 2 and differ[1] == differ[0] + 1
                                    and a[differ[0]] == b[differ[1]] and a[differ[1]] == b[differ[0]])
    short, long = sorted((a, b), key=len)
    return any(long[:i] + long[i + 1:] == short for i in range(len(long)))
