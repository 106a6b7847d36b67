//! `cargo xtask new-law NAME`: a new control law from the project's
//! template (`xtask/templates/law.rs`: a constant thrust in stance, the
//! flight PD in flight), written to `firmware/control/src/laws/NAME.rs` and
//! registered with one line in `laws!` (`firmware/control/src/laws/mod.rs`);
//! docs/parameters.md regenerated. Nothing else to edit: `hopper-sim run
//! --controller NAME` runs it, and `cargo xtask test` covers it with every
//! law (docs/laws.md).

use std::path::Path;

/// Where `laws!`'s list ends: the new line goes just above.
const MARKER: &str = "    // new laws: above this line";

/// A law's name as the command line and the link spell it: lower-case
/// letters, digits and single hyphens, starting with a letter, at most 24
/// characters (the link's parameter names hold the module and a field).
fn check_name(name: &str) -> Result<(), String> {
    let ok = name.len() <= 24
        && name.starts_with(|c: char| c.is_ascii_lowercase())
        && !name.ends_with('-')
        && !name.contains("--")
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
    if ok {
        Ok(())
    } else {
        Err(format!(
            "new-law: `{name}` is not a law name: lower-case letters, digits and single hyphens, starting with a letter, at most 24 characters (e.g. my-thrust)"
        ))
    }
}

/// `my-thrust` as `MyThrust`.
fn camel(name: &str) -> String {
    name.split('-')
        .map(|w| {
            let mut c = w.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// The next free parameter number: one past the largest declared in the
/// control crate (`NUMBER ID ...` lines of `config!`).
fn next_number(control: &Path) -> Result<u32, String> {
    let mut max = 0;
    let mut stack = vec![control.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let entries = std::fs::read_dir(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        for e in entries.flatten() {
            let path = e.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                let text = std::fs::read_to_string(&path).unwrap_or_default();
                for l in text.lines() {
                    let mut w = l.split_whitespace();
                    let (Some(n), Some(id)) = (w.next(), w.next()) else {
                        continue;
                    };
                    let is_id = id.len() > 1
                        && id
                            .chars()
                            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_');
                    if let (Ok(n), true) = (n.parse::<u32>(), is_id) {
                        max = max.max(n);
                    }
                }
            }
        }
    }
    Ok(max + 1)
}

/// `cargo xtask new-law NAME`.
pub fn run(root: &Path, name: &str) -> Result<(), String> {
    check_name(name)?;
    let module = name.replace('-', "_");
    let variant = camel(name);
    let laws = root.join("firmware/control/src/laws");
    let file = laws.join(format!("{module}.rs"));
    let registry = laws.join("mod.rs");
    let mod_text =
        std::fs::read_to_string(&registry).map_err(|e| format!("{}: {e}", registry.display()))?;
    if file.exists() || mod_text.contains(&format!("pub mod {module};")) {
        return Err(format!(
            "new-law: a law `{name}` exists already ({})",
            file.display()
        ));
    }
    if mod_text.contains(&format!("    {variant},")) || mod_text.contains(&format!(" {variant} =>"))
    {
        return Err(format!("new-law: a controller `{variant}` exists already"));
    }
    let Some(at) = mod_text.find(MARKER) else {
        return Err(format!(
            "new-law: no `{}` in {}",
            MARKER.trim(),
            registry.display()
        ));
    };
    let number = next_number(&root.join("firmware/control/src"))?;
    let template_path = root.join("xtask/templates/law.rs");
    let template = std::fs::read_to_string(&template_path)
        .map_err(|e| format!("{}: {e}", template_path.display()))?;
    let law = template
        .replace("{{name}}", name)
        .replace("{{module}}", &module)
        .replace("{{MODULE}}", &module.to_ascii_uppercase())
        .replace("{{Variant}}", &variant)
        .replace("{{number}}", &number.to_string());
    std::fs::write(&file, law).map_err(|e| format!("{}: {e}", file.display()))?;
    let line = format!(
        "    /// `{name}`: written by `cargo xtask new-law` ([`{module}`]).\n    {variant} => {module},\n"
    );
    let mut new_mod = mod_text.clone();
    new_mod.insert_str(at, &line);
    std::fs::write(&registry, new_mod).map_err(|e| format!("{}: {e}", registry.display()))?;
    println!("new-law: wrote {}", file.display());
    println!(
        "new-law: registered `{variant} => {module},` in {} (the last controller; parameter {module}.thrust_nm is number {number} on the link)",
        registry.display()
    );
    // The generated page of the parameter table.
    let status = crate::cargo()
        .current_dir(root)
        .env("HOPPER_WRITE_DOCS", "1")
        .args(["test", "-q", "-p", "hopper-control", "--lib", "params_doc"])
        .status()
        .map_err(|e| format!("new-law: cannot run cargo: {e}"))?;
    if !status.success() {
        return Err("new-law: regenerating docs/parameters.md failed (see above)".into());
    }
    println!("new-law: regenerated docs/parameters.md");
    println!(
        "new-law: try it: cargo run --release -p hal-sim --bin hopper-sim -- run --controller {name} --start-apex 0.1 --duration 3"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_become_modules_and_variants() {
        assert_eq!(camel("my-thrust"), "MyThrust");
        assert_eq!(camel("raibert2"), "Raibert2");
        for good in ["my-thrust", "a", "law-2-b"] {
            assert_eq!(check_name(good), Ok(()), "{good}");
        }
        for bad in [
            "",
            "My",
            "2law",
            "my_thrust",
            "my--thrust",
            "my-",
            "a-very-long-law-name-here-x",
        ] {
            assert!(check_name(bad).is_err(), "{bad}");
        }
    }
}
