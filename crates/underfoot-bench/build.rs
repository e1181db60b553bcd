//! Compiles the C anchors (`anchors/anchors.c`) with the system C compiler, twice: `-O3`,
//! the anchor the ratios are taken against, and `-O3 -march=native`, reported beside it.
//! Each build prefixes its symbols (`uf_o3_`, `uf_native_`) so that both link into one
//! bench. Without a C compiler (or when one build fails) the benches are built without
//! that anchor (`cfg(uf_c_anchor_o3)`, `cfg(uf_c_anchor_native)` unset) and say so.

fn main() {
    println!("cargo::rerun-if-changed=anchors/anchors.c");
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rustc-check-cfg=cfg(uf_c_anchor_o3)");
    println!("cargo::rustc-check-cfg=cfg(uf_c_anchor_native)");
    for (name, prefix, native) in [("o3", "uf_o3_", false), ("native", "uf_native_", true)] {
        let mut build = cc::Build::new();
        build
            .file("anchors/anchors.c")
            .define("UF_PREFIX", prefix)
            // Optimisation and warnings are this file's choice, not cargo's profile: the
            // anchor is the same `-O3` build whether the bench runs in test or bench mode.
            .opt_level(3)
            .debug(false)
            .flag_if_supported("-std=c99")
            .warnings(true);
        if native {
            build.flag_if_supported("-march=native");
        }
        let lib = format!("uf_anchors_{name}");
        match build.try_compile(&lib) {
            Ok(()) => {
                println!("cargo::rustc-cfg=uf_c_anchor_{name}");
                // The anchors call libm (exp, pow, ...).
                println!("cargo::rustc-link-lib=m");
                let compiler = build
                    .try_get_compiler()
                    .map(|c| c.path().display().to_string())
                    .unwrap_or_default();
                let flags = if native { "-O3 -march=native" } else { "-O3" };
                println!(
                    "cargo::rustc-env=UF_C_ANCHOR_{}={compiler} {flags}",
                    name.to_uppercase()
                );
            }
            Err(e) => {
                println!("cargo::warning=C anchor ({name}) not built: {e}");
                println!(
                    "cargo::rustc-env=UF_C_ANCHOR_{}_SKIPPED={}",
                    name.to_uppercase(),
                    e.to_string().replace('\n', " ")
                );
            }
        }
    }
}
