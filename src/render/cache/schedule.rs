//! Where the moving picture's fresh samples go: the holes first, row by row and the rows
//! coarse to fine, then 16 x 16 tiles by priority (how much their last samples changed, times
//! how long since they were visited), each tile's pixels in an ordered-dither order.

use super::RenderCache;

/// Side of the tiles samples are scheduled by.
pub const TILE: u32 = 16;

/// Pixels a tile gets per visit of [`RenderCache::next_pixels`].
const PER_VISIT: usize = 16;

/// Priority floor of a tile whose samples stopped changing: it is still visited as it ages.
const QUIET: f32 = 0.02;

/// Per-tile schedule state.
#[derive(Clone, Debug)]
pub(super) struct Tiles {
    pub(super) cols: u32,
    pub(super) rows: u32,
    /// How much the tile's last fresh samples differed from what its pixels held (0 to 1).
    pub(super) change: Vec<f32>,
    /// Calls of `next_pixels` since the tile was last given pixels.
    pub(super) age: Vec<u32>,
    /// Position of the tile in the ordered-dither order of its pixels.
    pub(super) cursor: Vec<u16>,
    /// Samples traced in the tile since [`RenderCache::take_work`].
    pub(super) work: Vec<u32>,
    /// Pixel offsets within a tile in ordered-dither order.
    pub(super) order: Vec<(u8, u8)>,
}

impl Tiles {
    /// The schedule of a `w x h` picture: every tile changed and just visited.
    pub(super) fn new(w: u32, h: u32) -> Self {
        let (cols, rows) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let n = (cols * rows) as usize;
        let mut order: Vec<(u8, u8)> = (0..TILE * TILE)
            .map(|i| ((i % TILE) as u8, (i / TILE) as u8))
            .collect();
        order.sort_by_key(|&(x, y)| bayer_rank(x as u32, y as u32));
        Tiles {
            cols,
            rows,
            change: vec![1.0; n],
            age: vec![0; n],
            cursor: vec![0; n],
            work: vec![0; n],
            order,
        }
    }
}

/// The rows in the order holes are traced: every eighth row first (0, 8, 16, ...), then the
/// rows halfway between (4, 12, ...), then 2, 6, ..., then the odd rows; within a row, left to
/// right. `pixels` come in row order and keep it within each of the eight groups. A fast turn
/// opens more holes than one picture's tracing fills: traced in plain row order, the top of the
/// picture was traced and its bottom filled for display from far away (blocks); in this order
/// the traced rows spread over all the holes and the fill spans a few rows.
pub(super) fn rows_coarse_to_fine(pixels: Vec<u32>, rows: Rows) -> Vec<u32> {
    // Row modulo 8 -> its group (three bits reversed).
    const GROUP: [usize; 8] = [0, 4, 2, 6, 1, 5, 3, 7];
    let group = |i: u32| GROUP[(rows.xy(i).1 % 8) as usize];
    let mut start = [0usize; 9];
    for &i in &pixels {
        start[group(i) + 1] += 1;
    }
    for g in 0..8 {
        start[g + 1] += start[g];
    }
    let mut out = vec![0u32; pixels.len()];
    for &i in &pixels {
        let g = group(i);
        out[start[g]] = i;
        start[g] += 1;
    }
    out
}

/// Splits pixel indices of a picture `width` wide into columns and rows with a multiply
/// instead of an integer division (which the compiler cannot take out of a loop over a width
/// known only at run time): for the camera rays, `is_dense` and `tile_of`, per sample.
#[derive(Clone, Copy, Debug)]
pub(super) struct Rows {
    width: u32,
    inv: f64,
}

impl Rows {
    pub(super) fn new(width: u32) -> Self {
        let width = width.max(1);
        Self {
            width,
            inv: 1.0 / f64::from(width),
        }
    }

    /// Column and row of pixel `i`. Exact for every `u32` index and width: `(i + 0.5) / width`
    /// lies at least `0.5 / width` from an integer, and the product's rounding error is below
    /// `2^-20 / width`.
    #[inline]
    pub(super) fn xy(self, i: u32) -> (u32, u32) {
        let y = ((f64::from(i) + 0.5) * self.inv) as u32;
        (i - y * self.width, y)
    }
}

/// The rank of a tile position in a 16 x 16 ordered-dither (Bayer) matrix: consecutive ranks
/// are far apart, so taking a tile's pixels in rank order covers it evenly.
fn bayer_rank(x: u32, y: u32) -> u32 {
    let mut rank = 0;
    for bit in (0..4).rev() {
        let (bx, by) = ((x >> bit) & 1, (y >> bit) & 1);
        rank = rank * 4 + ((bx ^ by) << 1 | by);
    }
    rank
}

impl RenderCache {
    pub(super) fn tile_of(&self, pixel: u32) -> usize {
        let (x, y) = self.rows.xy(pixel);
        ((y / TILE) * self.tiles.cols + x / TILE) as usize
    }

    /// About `count` pixels for fresh samples: the tiles of highest priority (how much their
    /// last samples changed, times how long since they were visited) get `PER_VISIT` pixels
    /// each, the next in their ordered-dither order.
    pub fn next_pixels(&mut self, count: usize) -> Vec<u32> {
        let t = &mut self.tiles;
        let n = t.change.len();
        let mut out = Vec::with_capacity(count);
        let mut visited = vec![false; n];
        while out.len() < count {
            let visits = (count - out.len()).div_ceil(PER_VISIT).min(n);
            let priority = |i: usize| (t.change[i] + QUIET) * (1 + t.age[i]) as f32;
            let mut ids: Vec<usize> = (0..n).collect();
            if visits < n {
                ids.select_nth_unstable_by(visits, |&a, &b| priority(b).total_cmp(&priority(a)));
                ids.truncate(visits);
            }
            // Neighbouring tiles next to each other, so packets of their pixels stay coherent.
            ids.sort_unstable();
            for &tile in &ids {
                visited[tile] = true;
                let (tx, ty) = (tile as u32 % t.cols * TILE, tile as u32 / t.cols * TILE);
                let mut given = 0;
                for _ in 0..TILE * TILE {
                    let (dx, dy) = t.order[t.cursor[tile] as usize];
                    t.cursor[tile] = ((t.cursor[tile] as u32 + 1) % (TILE * TILE)) as u16;
                    let (x, y) = (tx + dx as u32, ty + dy as u32);
                    if x < self.width && y < self.height {
                        out.push(y * self.width + x);
                        given += 1;
                        if given == PER_VISIT {
                            break;
                        }
                    }
                }
                // Visited tiles start aging again from zero; a second round in the same call
                // takes the rest in order.
                t.age[tile] = 0;
            }
        }
        for (age, v) in t.age.iter_mut().zip(&visited) {
            if !v {
                *age = age.saturating_add(1);
            }
        }
        out.truncate(count);
        out
    }

    /// Samples traced per tile since the last call (row by row of tiles), and zeroes them.
    pub fn take_work(&mut self) -> Vec<u32> {
        let n = self.tiles.work.len();
        std::mem::replace(&mut self.tiles.work, vec![0; n])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_tile_is_visited_and_each_visit_takes_new_pixels() {
        let mut c = RenderCache::new(40, 33, 1.0);
        let mut seen = vec![0u32; 40 * 33];
        // 9 tiles (3 x 3), the edge ones partly outside: enough calls cover every pixel.
        for _ in 0..200 {
            for i in c.next_pixels(64) {
                seen[i as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n > 0), "a pixel was never given");
        // With equal priorities the first visits go to different tiles.
        let mut c = RenderCache::new(64, 64, 1.0);
        let first = c.next_pixels(16 * PER_VISIT);
        let tiles: std::collections::HashSet<usize> = first.iter().map(|&i| c.tile_of(i)).collect();
        assert_eq!(tiles.len(), 16);
    }

    /// The Cornell box's soft shadows and bounces are noisy: tracing the same pixels of the
    /// same view again gives other samples, and the tiles' change shows it. With one sample
    /// index for every call the second call would repeat the first exactly, so a noisy tile
    /// would look settled and lose its priority.

    #[test]
    fn changed_tiles_get_pixels_first() {
        let mut c = RenderCache::new(64, 64, 1.0);
        c.tiles.change.iter_mut().for_each(|x| *x = 0.0);
        c.tiles.change[5] = 1.0;
        let first = c.next_pixels(PER_VISIT);
        assert!(first.iter().all(|&i| c.tile_of(i) == 5));
        // Its new samples matched what it held: the others, older, come next.
        c.tiles.change[5] = 0.0;
        let next = c.next_pixels(PER_VISIT);
        assert!(next.iter().all(|&i| c.tile_of(i) != 5));
    }

    #[test]
    fn holes_come_rows_coarse_to_fine() {
        let (w, h) = (7u32, 21u32);
        // Every third pixel of a 7 x 21 picture, in row order, as the reprojection finds them.
        let pixels: Vec<u32> = (0..w * h).filter(|i| i % 3 != 1).collect();
        let out = rows_coarse_to_fine(pixels.clone(), Rows::new(w));
        let mut sorted = out.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, pixels, "the same pixels");
        let rows: Vec<u32> = out.iter().map(|i| i / w).collect();
        let mut order: Vec<u32> = rows.clone();
        order.dedup();
        assert_eq!(
            order,
            [
                0, 8, 16, 4, 12, 20, 2, 10, 18, 6, 14, 1, 9, 17, 5, 13, 3, 11, 19, 7, 15
            ],
            "rows coarse to fine"
        );
        // Within a row, left to right.
        assert!(out.windows(2).all(|p| p[0] / w != p[1] / w || p[0] < p[1]));
    }

    #[test]
    fn rows_split_indices_as_integer_division_does() {
        for width in [1, 2, 3, 7, 16, 950, 1280, 4095, 7680, 65535] {
            let rows = Rows::new(width);
            let n = width * 3000;
            let near_rows = (0..3000u32).flat_map(|y| {
                let i = y * width;
                [i, i + width - 1, i.saturating_sub(1), i + 1]
            });
            for i in near_rows.chain([0, n - 1, u32::MAX - width, u32::MAX]) {
                assert_eq!(rows.xy(i), (i % width, i / width), "{i} in rows of {width}");
            }
        }
    }
}
