//! The traversal stack: child words and entry distances in two fixed arrays that are never
//! cleared. A ray's traversal starts with an empty stack, and zeroing the arrays for every ray
//! would cost more than a short traversal, so slots stay uninitialized until pushed.
//!
//! Children are pushed eight at a time ([`Stack::push8`]): all eight slots above the top are
//! written and the top moves up by the number of children actually hit, which lets the AVX2
//! kernel push with two stores and no branch.
#![allow(
    unsafe_code,
    reason = "reads of stack slots below `len`, which were all written"
)]

use std::mem::MaybeUninit;

use crate::bvh::MAX_DEPTH;
use crate::bvh::wide::WIDTH;

/// Room for every entry a traversal can hold (at most `WIDTH - 1` pending siblings per level
/// of the current path, and no path is deeper than the binary tree's [`MAX_DEPTH`]), plus the
/// `WIDTH` slots a [`Stack::push8`] writes above the top.
pub(crate) const CAPACITY: usize = (WIDTH - 1) * MAX_DEPTH + 2 * WIDTH;

/// The slots of a [`Stack`]: `(child word, entry distance)` pairs, uninitialized until pushed.
pub(crate) struct Slots {
    child: [MaybeUninit<u32>; CAPACITY],
    dist: [MaybeUninit<f32>; CAPACITY],
}

impl Slots {
    /// Slots with nothing written.
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            child: [const { MaybeUninit::uninit() }; CAPACITY],
            dist: [const { MaybeUninit::uninit() }; CAPACITY],
        }
    }
}

/// A stack of `(child word, entry distance)` with a fixed capacity. The slots are borrowed
/// and the length is kept beside them, so that the length lives in a register: kept in the
/// same struct as the arrays it stayed in memory, and every push and pop waited on the
/// store of the one before.
pub(crate) struct Stack<'a> {
    slots: &'a mut Slots,
    len: usize,
}

impl<'a> Stack<'a> {
    /// An empty stack over `slots` (nothing is written).
    #[inline(always)]
    pub fn new(slots: &'a mut Slots) -> Self {
        Self { slots, len: 0 }
    }

    /// Writes `child` and `dist` to the eight slots above the top, then keeps the first
    /// `count` (at most 8) as entries. Panics past [`CAPACITY`], which the depth bound of the
    /// builders rules out.
    #[inline(always)]
    pub fn push8(&mut self, child: [u32; WIDTH], dist: [f32; WIDTH], count: usize) {
        let d = &mut self.slots.dist[self.len..self.len + WIDTH];
        for k in 0..WIDTH {
            d[k].write(dist[k]);
        }
        self.push8_children(child, count);
    }

    /// Pushes one entry.
    #[inline(always)]
    pub fn push(&mut self, child: u32, dist: f32) {
        self.slots.dist[self.len].write(dist);
        self.push_child(child);
    }

    /// [`Stack::push8`] of child words alone, for walks that never read the distances back
    /// ([`Stack::pop_child`]).
    #[inline(always)]
    pub fn push8_children(&mut self, child: [u32; WIDTH], count: usize) {
        let top = self.len;
        let c = &mut self.slots.child[top..top + WIDTH];
        for k in 0..WIDTH {
            c[k].write(child[k]);
        }
        self.len = top + count.min(WIDTH);
    }

    /// Pushes a child word without a distance (see [`Stack::push8_children`]).
    #[inline(always)]
    pub fn push_child(&mut self, child: u32) {
        self.slots.child[self.len].write(child);
        self.len += 1;
    }

    /// Pops the top entry's child word. A stack that was pushed without distances must be
    /// popped with this alone.
    #[inline(always)]
    pub fn pop_child(&mut self) -> Option<u32> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every child slot below the old `len` was written by a push (each writes the
        // child slots it keeps), and `len` only grows through them.
        Some(unsafe { self.slots.child[self.len].assume_init() })
    }

    /// Pops the top entry.
    #[inline(always)]
    pub fn pop(&mut self) -> Option<(u32, f32)> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every slot below the old `len` was written by `push` or `push8` (which
        // writes eight slots and keeps at most eight), and `len` only grows through them.
        Some(unsafe {
            (
                self.slots.child[self.len].assume_init(),
                self.slots.dist[self.len].assume_init(),
            )
        })
    }
}

/// A stack of up to `N` copyable items whose slots stay uninitialized until pushed (the
/// packet traversal's, whose entries carry more than a child and a distance).
pub(crate) struct SmallStack<T: Copy, const N: usize> {
    buf: [MaybeUninit<T>; N],
    len: usize,
}

impl<T: Copy, const N: usize> SmallStack<T, N> {
    /// An empty stack (nothing is written).
    #[inline(always)]
    pub fn new() -> Self {
        Self {
            buf: [const { MaybeUninit::uninit() }; N],
            len: 0,
        }
    }

    /// Pushes an item. Panics past `N`.
    #[inline(always)]
    pub fn push(&mut self, item: T) {
        self.buf[self.len].write(item);
        self.len += 1;
    }

    /// Pops the top item.
    #[inline(always)]
    pub fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every slot below the old `len` was written by `push`, and `len` only grows
        // through `push`.
        Some(unsafe { self.buf[self.len].assume_init() })
    }
}
