"""One block-structure type: ``mu_blocks.BlockStructure`` validates a block list once and serves
the complex/real mu bounds (index maps, D-scaling parametrisation), the D-G scaling (shapes,
padding, the AB13MD description) and the certificate."""

from __future__ import annotations

import numpy as np
import pytest

from vtolftc.synthesis import dg_scaling, mixed_mu, mu, mu_blocks
from vtolftc.synthesis.mu_blocks import Block, BlockStructure


def test_every_analysis_uses_the_one_type() -> None:
    assert dg_scaling.BlockStructure is BlockStructure
    assert mixed_mu.BlockStructure is BlockStructure
    assert mu.Block is mu_blocks.Block
    assert not hasattr(mu, "BlockIndex")  # the second index type is gone


def test_built_from_a_structure_it_reuses_the_validated_maps() -> None:
    st = BlockStructure([Block.full(1, 3), Block.real(2)])
    assert "row_idx" not in vars(st)  # the index maps are built on first use ...
    assert st.row_idx[0].tolist() == [0, 1, 2] and "diag_param_l" in vars(st)  # ... all at once
    again = BlockStructure(st)
    assert again == st and hash(again) == hash(st)
    assert again.row_idx is st.row_idx and again.diag_param_l is st.diag_param_l
    with pytest.raises(AttributeError, match="immutable"):
        st.n = 3  # type: ignore[misc]


def test_index_maps_of_non_square_blocks() -> None:
    """M's rows are partitioned by the blocks' cols, its columns by their rows (mussv)."""
    st = BlockStructure([Block.full(1, 3), Block.full(3, 1)])
    assert st.m_shape == (4, 4) and st.delta_shape == (4, 4) and st.square
    assert [ix.tolist() for ix in st.row_idx] == [[0, 1, 2], [3]]
    assert [ix.tolist() for ix in st.col_idx] == [[0], [1, 2, 3]]
    assert st.blk_of_row.tolist() == [0, 0, 0, 1] and st.blk_of_col.tolist() == [0, 1, 1, 1]
    assert not st.all_square and st.n_params == 2 and not st.has_off
    assert st.ab13md_spec() is None
    assert st.require_square(4) is st
    with pytest.raises(ValueError, match="block sizes do not match M"):
        st.require_square(5)
    rect = BlockStructure([Block.full(1, 2)])
    assert rect.m_shape == (2, 1) and not rect.square


def test_repeated_blocks_get_full_triangular_scalings() -> None:
    st = BlockStructure([Block.repeated_complex(2), Block.full(1), Block.real(1)])
    # 2 log-diagonal + 2 (re, im) of one off-diagonal entry, then one each for the others
    assert st.n_params == 6 and st.has_off
    assert [s.start for s in st.block_param_slices] == [0, 4, 5]
    assert st.rep_blocks == [0, 2] and st.rep_row.tolist() == [0, 1, 3]
    assert st.is_real.tolist() == [False, False, True] and st.has_real
    assert st.ab13md_spec() is None
    spec = BlockStructure([Block.full(2), Block.real(1)]).ab13md_spec()
    assert spec is not None
    assert spec[0].tolist() == [2, 1] and spec[1].tolist() == [2, 1]
    assert spec[0].dtype == np.int64


def test_the_mu_functions_take_a_structure_or_a_list_alike() -> None:
    rng = np.random.default_rng(3)
    M = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
    blocks = [Block.full(1), Block.full(2)]
    a = mu.mu_bounds(M, blocks)
    b = mu.mu_bounds(M, BlockStructure(blocks))
    assert (a.lower, a.upper) == (b.lower, b.upper)
    c = mixed_mu.mixed_mu_upper(M, blocks)
    d = mixed_mu.mixed_mu_upper(M, BlockStructure(blocks))
    assert c.value == d.value
