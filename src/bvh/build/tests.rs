//! The builders' own test: building takes no denormal operand (the others, in `tests/`, compare
//! trees with brute force and across thread counts).

use super::*;
use crate::cpu::take_denormal_flag;
use crate::geometry::shapes;

/// Building takes no denormal operand: the triangle indices kept in the references' `w`
/// lanes read as denormals, and one multiplication of them per reference made every build
/// several times slower on an Intel Xeon (a microcode assist each). The builds run on a pool of one
/// thread, whose MXCSR the check reads, the triangles first so that loading them is not
/// counted.
#[test]
fn building_takes_no_denormal_operand() {
    let mut tris = shapes::icosphere(5);
    tris.extend(shapes::random_soup(20_000, 4.0, 7));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool of one thread");
    for options in [BuildOptions::sah(), BuildOptions::median()] {
        let took = pool.install(|| {
            take_denormal_flag();
            let bvh = build(&tris, &options);
            assert!(bvh.stats.leaves > 1);
            take_denormal_flag()
        });
        assert!(!took, "a {options:?} build took a denormal operand");
    }
}
