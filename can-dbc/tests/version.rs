//! `ugv-can --version` names the binary, its version and its crate.

#[test]
fn ugv_can_reports_its_name_version_and_crate() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ugv-can"))
        .arg("--version")
        .output()
        .expect("runs");
    assert!(out.status.success(), "{out:?}");
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        format!("ugv-can {} (golf-car-can)\n", env!("CARGO_PKG_VERSION")),
    );
}
