//! The traversal stack: a fixed array that is never cleared. A ray's traversal starts with an
//! empty stack, and zeroing the whole array for every ray would cost as much as a third of a
//! traversal on the canonical rays, so its slots stay uninitialized until pushed.
#![allow(
    unsafe_code,
    reason = "reads of stack slots below `len`, which were all written"
)]

use std::mem::MaybeUninit;

use crate::bvh::MAX_DEPTH;
use crate::bvh::wide::WIDTH;

/// A child still to visit: an inner node (`blocks == 0`) or a leaf's blocks, with the distance
/// at which the ray enters its box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Entry {
    pub child: u32,
    pub blocks: u32,
    pub dist: f32,
}

/// Room for every entry a traversal can hold: at most `WIDTH - 1` pending siblings per level
/// of the current path, and no path is deeper than the binary tree's [`MAX_DEPTH`].
pub(crate) const CAPACITY: usize = (WIDTH - 1) * MAX_DEPTH + WIDTH;

/// A stack of [`Entry`] with a fixed capacity.
pub(crate) struct Stack {
    buf: [MaybeUninit<Entry>; CAPACITY],
    len: usize,
}

impl Stack {
    /// An empty stack (nothing is written).
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            buf: [const { MaybeUninit::uninit() }; CAPACITY],
            len: 0,
        }
    }

    /// Number of entries.
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Pushes an entry. Panics past [`CAPACITY`], which the depth bound of the builders rules
    /// out.
    #[inline(always)]
    pub fn push(&mut self, e: Entry) {
        self.buf[self.len].write(e);
        self.len += 1;
    }

    /// Pops the top entry.
    #[inline(always)]
    pub fn pop(&mut self) -> Option<Entry> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every slot below the old `len` was written by `push` (or `sort_from`, which
        // only permutes written slots), and `len` only grows through `push`.
        Some(unsafe { self.buf[self.len].assume_init() })
    }

    /// Sorts the entries from `start` to the top by distance, the nearest on top.
    #[inline(always)]
    pub fn sort_from(&mut self, start: usize) {
        let top = self.len;
        // SAFETY: the slots `start..len` were all written by `push` (`start <= len`, checked by
        // the slice), and `MaybeUninit<Entry>` has the layout of `Entry`.
        let items: &mut [Entry] = unsafe {
            let s = &mut self.buf[start..top];
            std::slice::from_raw_parts_mut(s.as_mut_ptr().cast::<Entry>(), s.len())
        };
        // Insertion sort, farthest first: at most eight items.
        for i in 1..items.len() {
            let e = items[i];
            let mut j = i;
            while j > 0 && items[j - 1].dist < e.dist {
                items[j] = items[j - 1];
                j -= 1;
            }
            items[j] = e;
        }
    }
}
