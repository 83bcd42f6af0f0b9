"""Linear algebra of implicit steps on chain-structured Jacobians.

A chain couples each node to its neighbours only, so the Newton matrix of an implicit
step is banded (block tridiagonal with one node per block). Factorising it by block
elimination (sequential for 2 x 2 blocks, block cyclic reduction for larger ones)
costs O(k) per step instead of the O(k^3) of a dense LU.
"""

from .banded import (
    MIN_BANDED_SIZE as MIN_BANDED_SIZE,
    BandedFactor as BandedFactor,
    BCRFactor as BCRFactor,
    BlockTridiagonal as BlockTridiagonal,
    BorderedFactor as BorderedFactor,
    BorderedJacobian as BorderedJacobian,
    BorderedWidth as BorderedWidth,
    DenseFactor as DenseFactor,
    DenseJacobian as DenseJacobian,
    SecondOrderFactor as SecondOrderFactor,
    SecondOrderJacobian as SecondOrderJacobian,
    ThomasFactor as ThomasFactor,
    bcr_factor as bcr_factor,
    bcr_solve as bcr_solve,
    block_factor as block_factor,
    block_solve as block_solve,
    block_tridiagonal_jacobian as block_tridiagonal_jacobian,
    bordered_jacobian as bordered_jacobian,
    choose_structure as choose_structure,
    declared_second_order as declared_second_order,
    declared_sequential as declared_sequential,
    declared_width as declared_width,
    detect_width as detect_width,
    factor as factor,
    jacobian as jacobian,
    jacobian_directions as jacobian_directions,
    model_jacobian as model_jacobian,
    pivoted_inverse as pivoted_inverse,
    pivoted_solve as pivoted_solve,
    second_order_factor as second_order_factor,
    small_inv as small_inv,
    thomas_factor as thomas_factor,
    thomas_solve as thomas_solve,
)
