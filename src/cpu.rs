//! What the program asks of the CPU it runs on: which instruction sets it has (the proofs the
//! BVH's SIMD kernels are chosen by) and the floating-point mode the tracing and shading loops
//! run in (denormals flushed to zero).
//!
//! Every `unsafe` block here reads or writes the MXCSR register, each with its `SAFETY` reason.
#![allow(unsafe_code, reason = "reading and writing the MXCSR register")]

#[cfg(target_arch = "x86_64")]
pub use x86::*;

/// Runs `f` (elsewhere than on x86-64, as it is: the flush modes are x86's).
#[cfg(not(target_arch = "x86_64"))]
#[inline]
pub fn with_denormals_flushed<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    /// Proof that this CPU has AVX2 and FMA (and POPCNT, BMI1, BMI2 and LZCNT, which every AVX2
    /// CPU has and the mask bookkeeping uses: BMI2's `shrx` shifts without the flags and from
    /// memory, one instruction of the three in each step of the order scan): made only by
    /// [`Avx2Cpu::detect`].
    #[derive(Clone, Copy, Debug)]
    pub struct Avx2Cpu(());

    impl Avx2Cpu {
        /// The proof, when the CPU has both.
        pub fn detect() -> Option<Avx2Cpu> {
            (is_x86_feature_detected!("avx2")
                && is_x86_feature_detected!("fma")
                && is_x86_feature_detected!("popcnt")
                && is_x86_feature_detected!("bmi1")
                && is_x86_feature_detected!("bmi2")
                && is_x86_feature_detected!("lzcnt"))
            .then_some(Avx2Cpu(()))
        }
    }

    /// Proof that this CPU has AVX-512 F, VL, BW and DQ besides everything [`Avx2Cpu`] proves:
    /// made only by [`Avx512Cpu::detect`].
    #[derive(Clone, Copy, Debug)]
    pub struct Avx512Cpu(());

    impl Avx512Cpu {
        /// The proof, when the CPU has all of them.
        pub fn detect() -> Option<Avx512Cpu> {
            (Avx2Cpu::detect().is_some()
                && is_x86_feature_detected!("avx512f")
                && is_x86_feature_detected!("avx512vl")
                && is_x86_feature_detected!("avx512bw")
                && is_x86_feature_detected!("avx512dq"))
            .then_some(Avx512Cpu(()))
        }
    }

    /// The MXCSR of this thread (SSE, part of the x86-64 baseline).
    #[inline(always)]
    fn read_mxcsr() -> u32 {
        let mut csr = 0u32;
        // SAFETY: `stmxcsr` stores the 32-bit MXCSR to `csr`, a live local; it reads and writes
        // nothing else.
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &raw mut csr, options(nostack, preserves_flags))
        };
        csr
    }

    /// Loads `csr` into this thread's MXCSR.
    ///
    /// # Safety
    /// `csr` must be a valid MXCSR value: one read by [`read_mxcsr`], with at most its flags
    /// cleared or its flush-to-zero (bit 15) and denormals-are-zero (bit 6) modes set, which
    /// every x86-64 CPU supports (setting a reserved bit would fault).
    #[inline(always)]
    unsafe fn write_mxcsr(csr: u32) {
        // SAFETY: the caller passes a valid MXCSR value; `ldmxcsr` reads only `csr`.
        unsafe {
            std::arch::asm!("ldmxcsr [{}]", in(reg) &raw const csr, options(nostack, preserves_flags))
        };
    }

    /// Runs `f` with this thread's flush-to-zero and denormals-are-zero modes on (MXCSR bits 15
    /// and 6), and puts the register back afterwards, on unwinding too. Inside, a denormal
    /// operand reads as zero and a denormal result is written as zero, so no instruction takes
    /// the microcode assist Intel CPUs need for denormals; the compiler's vector code for
    /// three-float arithmetic computes spare lanes of whatever the registers and the stack held,
    /// often a denormal (the renderer's shading runs inside it for that reason).
    #[inline]
    pub fn with_denormals_flushed<R>(f: impl FnOnce() -> R) -> R {
        const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);
        struct Restore(u32);
        impl Drop for Restore {
            fn drop(&mut self) {
                // SAFETY: the value read on entry.
                unsafe { write_mxcsr(self.0) }
            }
        }
        let saved = read_mxcsr();
        let _restore = Restore(saved);
        // SAFETY: the value read, with the two modes every x86-64 CPU has set.
        unsafe { write_mxcsr(saved | FTZ_DAZ) };
        f()
    }

    /// Whether an SSE or AVX instruction of this thread took a denormal operand since the last
    /// call: the MXCSR's sticky denormal flag (DE, bit 1), which this clears. Arithmetic on
    /// denormals costs Intel CPUs a microcode assist per instruction (a hundred cycles or more),
    /// so tests check that the fast paths never take one (the flag is architectural: AMD CPUs,
    /// which take no such penalty, set it too, so the tests catch it on either).
    #[cfg(test)]
    pub(crate) fn take_denormal_flag() -> bool {
        const DE: u32 = 1 << 1;
        let csr = read_mxcsr();
        // SAFETY: the value read, with only the sticky DE flag cleared: the rounding mode,
        // exception masks and flush modes stay what they were.
        unsafe { write_mxcsr(csr & !DE) };
        csr & DE != 0
    }
}
