//! `underfoot export`: a library as a C header, refused when it fails the check.

use std::fs;

use crate::common::{assert_error, assert_ok, run, s, stdout, write_library};

#[test]
fn export_writes_a_c_header_and_refuses_what_fails_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let lib = write_library(dir.path(), &["tile", "board"]);
    let out = dir.path().join("materials.h");
    let o = run(&[
        "export",
        "--format",
        "c",
        "--out",
        s(&out),
        "--library",
        s(&lib),
        "--materials",
        "board",
    ]);
    assert_ok(&o);
    let table = stdout(&o);
    assert!(
        table.contains("board") && !table.contains("tile"),
        "{table}"
    );
    let header = fs::read_to_string(&out).unwrap();
    assert!(header.contains("#define UF_MATERIAL_COUNT 1u"));
    assert!(header.contains("\"board\"") && header.contains("uf_q31_cascade"));
    // Both fixed-point formats by default; `--fixed` picks.
    assert!(header.contains("uf_m0_board_q15[") && header.contains("uf_m0_board_q31["));
    let only = dir.path().join("q31.h");
    assert_ok(&run(&[
        "export",
        "--out",
        s(&only),
        "--library",
        s(&lib),
        "--materials",
        "board",
        "--fixed",
        "q31",
    ]));
    let q31_only = fs::read_to_string(&only).unwrap();
    assert!(!q31_only.contains("uf_m0_board_q15[") && q31_only.contains("uf_m0_board_q31["));

    // An unknown material, and a tolerance no quantised filter meets: status 1, named.
    let e = assert_error(&run(&[
        "export",
        "--out",
        s(&out),
        "--library",
        s(&lib),
        "--materials",
        "lava",
    ]));
    assert!(e.contains("lava"), "{e}");
    let e = assert_error(&run(&[
        "export",
        "--out",
        s(&out),
        "--library",
        s(&lib),
        "--fixed",
        "q15",
        "--tolerance-db",
        "1e-9",
    ]));
    assert!(e.contains("Q15") && e.contains(" Hz"), "{e}");
    // The failed export left the earlier header in place.
    assert_eq!(fs::read_to_string(&out).unwrap(), header);
}
