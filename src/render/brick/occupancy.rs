//! Which sub-blocks of a decoded brick hold a 1-cell: what the culling of
//! a turntable's later frames projects instead of whole bricks
//! (render/view/cull.rs). The brick index knows only whether a brick holds a
//! 1-cell; once a brick is decoded, its code plane says where.

use super::{Codes, RBrick};
use crate::render::traverse::OBJECT;

/// Sub-blocks per brick edge in [`Occupancy`] masks: 4 cells per edge on
/// the default 32-cell bricks.
pub const SUB: u32 = 8;

/// Which of a brick's [`SUB`]^3 sub-blocks (`brick_size.div_ceil(SUB)`
/// cells per edge, the last ones clipped to the brick) hold a 1-cell: bit
/// `(z * SUB + y) * SUB + x` of the words taken as one little-endian bit
/// string.
pub type Occupancy = [u64; MASK_WORDS];

/// `u64` words of an [`Occupancy`].
const MASK_WORDS: usize = (SUB * SUB * SUB).div_ceil(64) as usize;

/// The [`Occupancy`] of decoded brick `b` on bricks of `brick_size` cells
/// per edge, from its code plane (255: 1-cell). 255 is the largest code,
/// so the bytewise maximum of a sub-block row's code rows (a loop the
/// compiler vectorises) holds 255 where one of them holds a 1-cell: one
/// scan of that row per sub-block row (about 60,000 instructions a 32^3
/// brick).
pub fn occupancy(b: &RBrick, brick_size: u32) -> Occupancy {
    let mut mask = Occupancy::default();
    let p = match &b.codes {
        Codes::Plane(p) => p,
        // One code for every cell (never a 1-cell's today, but that would
        // mark every sub-block).
        Codes::Uniform(c) if *c == OBJECT => return [u64::MAX; MASK_WORDS],
        Codes::Uniform(_) => return mask,
    };
    let e = brick_size.div_ceil(SUB) as usize;
    let [nx, ny, nz] = b.cells.map(|c| c as usize);
    let mut top = vec![0u8; nx];
    for zb in 0..nz.div_ceil(e) {
        for yb in 0..ny.div_ceil(e) {
            top.fill(0);
            for z in zb * e..((zb + 1) * e).min(nz) {
                for y in yb * e..((yb + 1) * e).min(ny) {
                    let row = &p[(z * ny + y) * nx..][..nx];
                    for (t, &c) in top.iter_mut().zip(row) {
                        *t = (*t).max(c);
                    }
                }
            }
            let base = (zb * SUB as usize + yb) * SUB as usize;
            for (xb, seg) in top.chunks(e).enumerate() {
                if seg.contains(&OBJECT) {
                    let bit = base + xb;
                    mask[bit / 64] |= 1 << (bit % 64);
                }
            }
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::brick::samples::Samples;
    use proptest::prelude::*;

    fn brick(cells: [u32; 3], codes: Codes) -> RBrick {
        RBrick::bare([0; 3], cells, codes, Samples::Empty)
    }

    proptest! {
        /// Each bit against its sub-block's cells, scanned one by one, on
        /// bricks of every size from 1 to 40 cells per edge (clipped at
        /// the volume's edge or not) and sparse or dense 1-cells.
        #[test]
        fn occupancy_marks_exactly_the_sub_blocks_with_a_1_cell(
            size in 1u32..41,
            clip in (0u32..40, 0u32..40, 0u32..40),
            dense in 0u32..100,
            seed in any::<u64>(),
        ) {
            let cells = [clip.0, clip.1, clip.2].map(|c| size - c % size);
            let n = cells.iter().product::<u32>() as usize;
            let mut x = seed | 1;
            let codes: Vec<u8> = (0..n)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    if (x % 1000) < dense as u64 { OBJECT } else { (x % 7) as u8 }
                })
                .collect();
            let m = occupancy(&brick(cells, Codes::Plane(codes.clone())), size);
            let e = size.div_ceil(SUB);
            for bit in 0..(SUB * SUB * SUB) {
                let s = [bit % SUB, bit / SUB % SUB, bit / (SUB * SUB)];
                let mut any = false;
                for z in s[2] * e..((s[2] + 1) * e).min(cells[2]) {
                    for y in s[1] * e..((s[1] + 1) * e).min(cells[1]) {
                        for x in s[0] * e..((s[0] + 1) * e).min(cells[0]) {
                            let i = ((z * cells[1] + y) * cells[0] + x) as usize;
                            any |= codes[i] == OBJECT;
                        }
                    }
                }
                let got = m[bit as usize / 64] >> (bit % 64) & 1 == 1;
                prop_assert_eq!(got, any, "bit {} of a brick of {:?}", bit, cells);
            }
        }
    }

    #[test]
    fn a_brick_of_one_code_has_no_occupied_sub_block() {
        for c in [0, 7, 254] {
            let m = occupancy(&brick([32; 3], Codes::Uniform(c)), 32);
            assert_eq!(m, Occupancy::default());
        }
    }
}
