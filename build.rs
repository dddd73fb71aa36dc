//! The source revision gyrobench was built from, for every log, report and
//! coefficient set it writes: `GYROBENCH_REVISION` when set (a packager's
//! build from a tarball), else the git commit of the checkout (with
//! `-dirty` when tracked files differ from it), else `unknown`.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        // Never take git's index lock: a build must not race a commit.
        .arg("--no-optional-locks")
        .args(args)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

fn main() {
    println!("cargo:rerun-if-env-changed=GYROBENCH_REVISION");
    let given = std::env::var("GYROBENCH_REVISION")
        .ok()
        .filter(|s| !s.trim().is_empty());
    let revision = given.or_else(|| {
        let commit = git(&["rev-parse", "--short=12", "HEAD"])?;
        // A new commit (HEAD moves, or the branch it names) or a changed
        // source file asks again.
        // Only files that exist: cargo takes a missing one as changed on
        // every build, and rebuilds the crate each time (a repository
        // whose refs are all loose has no `packed-refs`).
        if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
            let mut watched = vec![format!("{dir}/HEAD"), format!("{dir}/packed-refs")];
            if let Some(r) = git(&["symbolic-ref", "-q", "HEAD"]) {
                watched.push(format!("{dir}/{r}"));
            }
            for path in watched {
                if std::path::Path::new(&path).exists() {
                    println!("cargo:rerun-if-changed={path}");
                }
            }
        }
        // Everything tracked that goes into the binary: the sources, the
        // fixtures it embeds (the default twin), the manifest and the lock.
        for path in ["src", "crates", "fixtures", "Cargo.toml", "Cargo.lock"] {
            println!("cargo:rerun-if-changed={path}");
        }
        let dirty =
            git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
        Some(if dirty {
            format!("{commit}-dirty")
        } else {
            commit
        })
    });
    println!(
        "cargo:rustc-env=GYROBENCH_REVISION={}",
        revision.unwrap_or_else(|| "unknown".into())
    );
}
