//! The CPU instruction sets the pipeline's hot loops are compiled for, and which one runs.
//!
//! Every multiversioned function of the pipeline (`#[multiversion(targets(...))]`) is compiled
//! for exactly [`TARGETS`] plus the baseline of the build target (x86-64: SSE2; aarch64: NEON,
//! which needs no dispatch). The attribute cannot take a constant, so the list is written out
//! at each function and a test (`one_target_list_everywhere`) holds them to this one. Which
//! version runs is decided at run time from the CPU ([`level`]), so one binary serves a
//! desktop with AVX-512, a laptop with AVX2 and a board or old x86 without either.
//!
//! The versions compute the same results: the code never asks for fused multiply-adds or
//! reassociation, so a wider instruction set changes only how many lanes run at once, not
//! the rounding. `scripts/test-cpu-levels.sh` runs the unit tests under `qemu-x86_64 -cpu`
//! with AVX2 and with neither (`DEAR_EXPECT_SIMD` makes [`level`]'s test check that the
//! emulated CPU really dispatches where the tier says).

/// The x86-64 targets of every multiversioned function, widest first, as the attribute spells
/// them. `avx512bw` for the byte and word loops, `fma` because every AVX2 CPU has it.
pub const TARGETS: [&str; 2] = ["x86_64+avx512f+avx512bw+avx512vl+fma", "x86_64+avx2+fma"];

/// The instruction set the multiversioned functions dispatch to on this CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// AVX-512 F, BW and VL with FMA: the first of [`TARGETS`].
    Avx512,
    /// AVX2 with FMA: the second of [`TARGETS`].
    Avx2,
    /// The build target's baseline: SSE2 on x86-64, NEON on aarch64.
    Baseline,
}

impl Level {
    /// The name `DEAR_EXPECT_SIMD` and the logs use.
    pub fn name(self) -> &'static str {
        match self {
            Level::Avx512 => "avx512",
            Level::Avx2 => "avx2",
            Level::Baseline => "baseline",
        }
    }
}

/// The level this CPU runs (the same test multiversion's dispatch makes).
pub fn level() -> Level {
    #[cfg(target_arch = "x86_64")]
    {
        let avx512 = std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512bw")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("fma");
        if avx512 {
            return Level::Avx512;
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            return Level::Avx2;
        }
    }
    Level::Baseline
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Under `scripts/test-cpu-levels.sh` each emulated CPU must dispatch where the tier says,
    /// or the tier would test the wrong versions and pass.
    #[test]
    fn dispatch_level_is_what_the_tier_expects() {
        let got = level();
        if let Ok(want) = std::env::var("DEAR_EXPECT_SIMD") {
            assert_eq!(got.name(), want, "this CPU dispatches to {got:?}");
        }
    }

    fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                rust_files(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }

    /// The attribute's opening, spelt so that this file's own code does not match it.
    const ATTRIBUTE: &str = concat!("multiversion::", "multiversion(");

    /// Every multiversioned function of the pipeline names [`TARGETS`], in order. (deard-bench's
    /// peak probe names its one instruction set on purpose: it measures that set.)
    #[test]
    fn one_target_list_everywhere() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        assert!(root.join("pipeline").join("src").is_dir());
        let want = format!(
            "targets({})",
            TARGETS.map(|t| format!("\"{t}\"")).join(", ")
        );
        let mut files = Vec::new();
        rust_files(&root.join("pipeline").join("src"), &mut files);
        let mut seen = 0;
        for file in files {
            let text = std::fs::read_to_string(&file).unwrap();
            for (n, line) in text.lines().enumerate() {
                let Some(at) = line.find(ATTRIBUTE) else {
                    continue;
                };
                if line.trim_start().starts_with("//") {
                    continue;
                }
                seen += 1;
                let args = &line[at + ATTRIBUTE.len()..];
                assert!(
                    args.starts_with(&want),
                    "{}:{}: multiversion targets differ from simd::TARGETS ({want})",
                    file.display(),
                    n + 1
                );
            }
        }
        assert!(seen >= 10, "found only {seen} multiversioned functions");
    }
}
