"""The bare ModalBank kernel called per block from compiled code: the reference that
``jassy bench modal``'s graph figure is compared with (what a graph does per block,
without the graph)."""

import numba as nb

from jassy import anytime_rank
from jassy.jit import drop_stale_cache
from ugens import cells, modal
from ugens.modal import mode_rows, resonate

drop_stale_cache(__file__, [anytime_rank, cells, modal])  # the cache holds copies of resonate's kernels


@nb.njit(cache=True)
def resonate_blocks(force, out, bank, block, last):
    """:func:`ugens.modal.resonate` over ``force`` into ``out`` in calls of ``block``
    frames; bank rows c1, c2, g, d, y1, y2; last[0] as in resonate."""
    k = bank.shape[1]
    for s in range(0, force.size, block):
        n = min(block, force.size - s)
        resonate(force[s:], out[s:], n, mode_rows(bank), k, last)
