//! The central traits' sizes, capped (issue "Seams before the second backend"): what one or two
//! implementors need becomes a role they return (`terms::roles`), not a method every
//! implementor carries. As the Python import test guards that package's layering, this test
//! guards these traits from growing back; raise a cap only with the reason in the commit.

/// The methods declared in `pub trait NAME` of `src` (a file's text), split into role
/// accessors (`as_…`) and the rest.
fn methods(src: &str, name: &str) -> (Vec<String>, Vec<String>) {
    let start = src.find(&format!("pub trait {name}")).unwrap_or_else(|| panic!("no trait {name}"));
    let body = &src[start..];
    // The trait's block: from its first '{' to the matching '}'.
    let open = body.find('{').expect("a trait body");
    let (mut depth, mut end) = (0usize, open);
    for (i, c) in body[open..].char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    end = open + i;
                    break;
                }
            }
            _ => {}
        }
    }
    let (mut roles, mut rest) = (Vec::new(), Vec::new());
    // A method is declared at the trait's own depth (4 spaces), so a `fn` inside a default
    // body is not counted.
    for line in body[open..end].lines() {
        if let Some(sig) = line.strip_prefix("    fn ") {
            let name = sig.split(['(', '<']).next().unwrap_or_default().to_string();
            if name.starts_with("as_") {
                roles.push(name);
            } else {
                rest.push(name);
            }
        }
    }
    (roles, rest)
}

#[test]
fn central_traits_stay_small() {
    let caps = [
        // (file, trait, role accessors, other methods)
        (include_str!("terms/mod.rs"), "Term", 9, 12),
        // 3 roles: the rigid bodies, and the terms a device system holds (`HeldTerms`, read
        // and loaded: two accessors, since the bindings read it through a shared borrow).
        (include_str!("systems/mod.rs"), "System", 3, 23),
        (include_str!("systems/mod.rs"), "Coupling", 0, 4),
        (include_str!("integrators/mod.rs"), "Integrator", 4, 11),
    ];
    for (src, name, max_roles, max_rest) in caps {
        let (roles, rest) = methods(src, name);
        assert!(
            roles.len() <= max_roles && rest.len() <= max_rest,
            "trait {name} has {} role accessors (cap {max_roles}) and {} other methods (cap {max_rest}): \
             {roles:?} {rest:?}; what one or two implementors need belongs in a role",
            roles.len(),
            rest.len()
        );
        assert!(!rest.is_empty(), "trait {name}: no methods found (the parser no longer reads it)");
    }
}
