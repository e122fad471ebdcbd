//! Helpers shared by the end-to-end tests.

use std::path::PathBuf;
use std::process::{Command, Output};

/// A vcan interface of the test's own, deleted on drop, so tests run in parallel.
///
/// Creating it fails loudly (with the reason and what to do) when this kernel has no
/// vcan or the process lacks CAP_NET_ADMIN: the README's test command runs these
/// tests on a host with vcan or inside `vcan-setup vm`.
#[derive(Debug)]
pub struct TestVcan {
    pub name: String,
}

impl TestVcan {
    /// `tag` (up to 6 characters) names the test; the process ID makes it unique.
    pub fn new(tag: &str) -> anyhow::Result<TestVcan> {
        let name = format!(
            "vt{}{}",
            &tag[..tag.len().min(6)],
            std::process::id() % 100_000
        );
        vcan_setup::up(&name).map_err(|e| {
            anyhow::anyhow!("this test needs a vcan interface and could not create {name}: {e}")
        })?;
        Ok(TestVcan { name })
    }
}

impl Drop for TestVcan {
    fn drop(&mut self) {
        let _ = vcan_setup::down(&self.name);
    }
}

/// Run a can-utils tool and return its output, naming the package when it is missing.
pub fn can_utils(tool: &str, args: &[&str]) -> anyhow::Result<Output> {
    Command::new(tool).args(args).output().map_err(|e| {
        anyhow::anyhow!(
            "running {tool} (Debian package can-utils, see scripts/install-deps.sh): {e}"
        )
    })
}

/// A binary of the workspace: from `UGV_BIN_DIR` when set (the test command points
/// it at the release build for the real-time runs), else the one built by
/// `cargo build --workspace` beside this test (target/<profile>/NAME).
pub fn workspace_bin(name: &str) -> anyhow::Result<PathBuf> {
    let dir = match std::env::var_os("UGV_BIN_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => {
            // target/<profile>/deps/<test>-<hash>
            let exe = std::env::current_exe()?;
            exe.parent()
                .and_then(|deps| deps.parent())
                .map(std::path::Path::to_path_buf)
                .ok_or_else(|| {
                    anyhow::anyhow!("cannot locate the target directory from {}", exe.display())
                })?
        }
    };
    let bin = dir.join(name);
    anyhow::ensure!(
        bin.is_file(),
        "{} is missing: build the workspace first (cargo build --workspace, --release for UGV_BIN_DIR=target/release)",
        bin.display()
    );
    Ok(bin)
}
