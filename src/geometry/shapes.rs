//! Triangles made in code: the shapes scene files name, and stress meshes for tests and
//! benchmarks.

use glam::Vec3;

/// A unit icosphere: an icosahedron whose faces are split in four `subdivisions` times and
/// pushed onto the unit sphere (20 * 4^n triangles, outward winding).
pub fn icosphere(subdivisions: u32) -> Vec<[Vec3; 3]> {
    let t = (1.0 + 5.0f32.sqrt()) / 2.0;
    let v = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .map(|p| Vec3::from(p).normalize());
    let f: [[usize; 3]; 20] = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let mut tris: Vec<[Vec3; 3]> = f.iter().map(|f| f.map(|i| v[i])).collect();
    for _ in 0..subdivisions {
        tris = tris
            .iter()
            .flat_map(|&[a, b, c]| {
                let ab = ((a + b) * 0.5).normalize();
                let bc = ((b + c) * 0.5).normalize();
                let ca = ((c + a) * 0.5).normalize();
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    tris
}

/// The cube `[-0.5, 0.5]^3`: 12 triangles, outward winding.
pub fn cube() -> Vec<[Vec3; 3]> {
    let mut tris = Vec::with_capacity(12);
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let n = Vec3::from_array(std::array::from_fn(|i| if i == axis { sign } else { 0.0 }));
            let u = Vec3::from_array(std::array::from_fn(|i| {
                if i == (axis + 1) % 3 { 1.0 } else { 0.0 }
            }));
            let v = n.cross(u);
            let c = n * 0.5;
            let (a, b, cc, d) = (
                c - 0.5 * u - 0.5 * v,
                c + 0.5 * u - 0.5 * v,
                c + 0.5 * u + 0.5 * v,
                c - 0.5 * u + 0.5 * v,
            );
            tris.push([a, b, cc]);
            tris.push([a, cc, d]);
        }
    }
    tris
}

/// The unit square in the plane `y = 0`, `[-0.5, 0.5]` in x and z, facing `+y`.
pub fn quad() -> Vec<[Vec3; 3]> {
    let a = Vec3::new(-0.5, 0.0, -0.5);
    let b = Vec3::new(0.5, 0.0, -0.5);
    let c = Vec3::new(0.5, 0.0, 0.5);
    let d = Vec3::new(-0.5, 0.0, 0.5);
    vec![[a, d, c], [a, c, b]]
}

/// A grid of `n x n` cells, two triangles each, over `[0, size]^2` in the plane `z = 0`:
/// many tiny triangles that share edges and vertices.
pub fn grid(n: u32, size: f32) -> Vec<[Vec3; 3]> {
    let h = size / n as f32;
    let p = |i: u32, j: u32| Vec3::new(i as f32 * h, j as f32 * h, 0.0);
    let mut tris = Vec::with_capacity((2 * n * n) as usize);
    for j in 0..n {
        for i in 0..n {
            tris.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            tris.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    tris
}

/// A rolling terrain of `n x n` cells, two triangles each (`2 n^2` triangles): the grid of
/// [`grid`] over the unit square with heights from a sum of sines, a large mesh with the
/// shape of a real surface for build-time measurements.
pub fn terrain(n: u32) -> Vec<[Vec3; 3]> {
    let height = |x: f32, y: f32| {
        0.05 * ((x * 17.0).sin() * (y * 13.0).cos() + 0.5 * (x * 41.0 + y * 37.0).sin())
    };
    grid(n, 1.0)
        .into_iter()
        .map(|t| t.map(|v| Vec3::new(v.x, v.y, height(v.x, v.y))))
        .collect()
}

/// `count` needle triangles (length to width ratio `aspect`) fanned around the `y` axis at
/// slightly different heights: long, thin boxes that overlap a lot.
pub fn needles(count: u32, aspect: f32) -> Vec<[Vec3; 3]> {
    let width = 1.0 / aspect;
    (0..count)
        .map(|i| {
            let a = i as f32 / count as f32 * std::f32::consts::TAU;
            let dir = Vec3::new(a.cos(), 0.0, a.sin());
            let side = Vec3::new(-a.sin(), 0.0, a.cos()) * width;
            let y = Vec3::Y * (i as f32 / count as f32);
            [y, y + dir + side, y + dir - side * 0.5 + Vec3::Y * width]
        })
        .collect()
}

/// A deterministic soup of `count` random triangles in the unit cube (sizes up to `size`),
/// from a small xorshift generator.
pub fn random_soup(count: u32, size: f32, seed: u64) -> Vec<[Vec3; 3]> {
    let mut rng = crate::rng::SplitMix64::new(seed);
    (0..count)
        .map(|_| {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let mut v = || {
                c + size
                    * Vec3::new(
                        rng.next_f32() - 0.5,
                        rng.next_f32() - 0.5,
                        rng.next_f32() - 0.5,
                    )
            };
            [v(), v(), v()]
        })
        .collect()
}
