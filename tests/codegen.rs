//! What the compiler made of the AVX-512 kernel (x86-64 only), read from this test binary's own
//! disassembly (`objdump` from binutils): the single-ray walks hold no 512-bit instruction.
//!
//! With AVX-512 enabled the compiler may join scalar and 256-bit memory operations into 512-bit
//! ones. It once put 12 into the closest-hit walk (the pair test's answer zeroed, two of its
//! lanes read), and on an Intel Xeon that walk ran 8-9% slower than the same code
//! compiled for AVX2 alone. The walk's code is not timed here (timings belong in benchmarks):
//! its instructions are checked, which a change to the walks can break.

#![cfg(target_arch = "x86_64")]

use std::collections::BTreeMap;
use std::process::Command;

use glam::Vec3;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::geometry::Ray;
use tracery::geometry::shapes;

/// Per function whose demangled name contains `part`: its instruction count and the
/// instructions that name a 512-bit register.
fn functions(disassembly: &str, part: &str) -> BTreeMap<String, (usize, Vec<String>)> {
    let mut found = BTreeMap::new();
    let mut current: Option<String> = None;
    for line in disassembly.lines() {
        // A function starts with a line `address <name>:`.
        if let Some((address, name)) = line.strip_suffix(">:").and_then(|l| l.split_once(" <")) {
            current = name.contains(part).then(|| format!("{name} at {address}"));
            continue;
        }
        let Some(name) = &current else { continue };
        // Instruction lines are `  address:\tmnemonic operands`.
        let Some((_, instruction)) = line.split_once(":\t") else {
            continue;
        };
        let entry = found.entry(name.clone()).or_insert_with(|| (0, Vec::new()));
        entry.0 += 1;
        if instruction.contains("%zmm") {
            entry.1.push(instruction.trim().to_string());
        }
    }
    found
}

#[test]
fn the_avx512_kernels_single_ray_walks_use_no_512_bit_registers() {
    // Every query traced once, so that each kernel's walks are linked into this binary
    // whatever this CPU runs (the dispatch names every kernel's entry points).
    let tris = shapes::icosphere(2);
    let bvh = Bvh::build(&tris, &BuildOptions::sah());
    let rays: Vec<Ray> = (0..64)
        .map(|i| {
            let x = (i % 8) as f32 / 4.0 - 1.0;
            let y = (i / 8) as f32 / 4.0 - 1.0;
            Ray::new(Vec3::new(x, y, -5.0), Vec3::Z)
        })
        .collect();
    let mut hits = vec![None; rays.len()];
    bvh.intersect_packet(&rays, f32::INFINITY, &mut hits);
    for (ray, packet_hit) in rays.iter().zip(&hits) {
        assert_eq!(bvh.intersect(ray, f32::INFINITY), *packet_hit);
        assert_eq!(bvh.intersect_incoherent(ray, f32::INFINITY), *packet_hit);
        assert_eq!(bvh.occluded(ray, f32::INFINITY), packet_hit.is_some());
    }
    assert!(hits.iter().any(Option::is_some), "the rays miss the sphere");

    let exe = std::env::current_exe().expect("the test binary's path");
    let out = Command::new("objdump")
        .args(["-d", "--no-show-raw-insn", "-C"])
        .arg(&exe)
        .output()
        .expect("objdump (Debian's binutils) runs");
    assert!(
        out.status.success(),
        "objdump failed on {}: {}",
        exe.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);

    let walks = functions(&text, "kernel::avx512::closest_inner");
    let any_hit = functions(&text, "kernel::avx512::each_hit_inner");
    let packets = functions(&text, "kernel::avx512::trace_packet_inner");
    assert!(
        !walks.is_empty() && !any_hit.is_empty() && !packets.is_empty(),
        "the AVX-512 walks were not found in {} (closest {}, any hit {}, packets {})",
        exe.display(),
        walks.len(),
        any_hit.len(),
        packets.len()
    );
    // The packet walk uses 512-bit registers by design (groups of sixteen rays): the check
    // sees them where they are.
    assert!(
        packets.values().all(|(_, zmm)| !zmm.is_empty()),
        "no 512-bit register found in the packet walk: the check reads nothing"
    );
    // The closest-hit walk's four forms (the NaN rule or not, coherent or incoherent rays).
    assert!(
        walks.len() >= 4,
        "closest-hit walks found: {:?}",
        walks.keys()
    );
    for (name, (count, zmm)) in walks.iter().chain(&any_hit) {
        assert!(*count > 100, "{name}: only {count} instructions read");
        assert!(
            zmm.is_empty(),
            "{name} has {} instructions on 512-bit registers, e.g. {:?}",
            zmm.len(),
            &zmm[..zmm.len().min(4)]
        );
    }
}
