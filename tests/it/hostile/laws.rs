//! Law files read as a careless or hostile author writes them: compiling costs what the
//! expression's size suggests (derivatives bounded before they are built, WGSL linear in the
//! expression), constants beyond f32 are named, a law that loses digits in f32 is blamed and
//! not the GPU, and no name of a law can collide with another's columns or bitrock's own words.

use super::{assert_refused, names, run_in, small_run};
use std::path::Path;

/// A law file `name.toml` in `dir` with `torque` and parameters tc (N·m) and g (s/rad).
fn law_file(dir: &Path, name: &str, torque: &str) {
    std::fs::write(
        dir.join(format!("{name}.toml")),
        format!(
            "name = \"{name}\"\ntorque = \"{torque}\"\n\n[[parameter]]\nname = \"tc\"\nunit = \"N·m\"\nreference = 6500\n\n\
             [[parameter]]\nname = \"g\"\nunit = \"s/rad\"\nreference = 0.3\n"
        ),
    )
    .unwrap();
}

#[test]
fn compiling_a_law_costs_what_its_size_suggests() {
    let tmp = tempfile::tempdir().unwrap();
    // A product of 700 factors: its derivatives would hold of order n² nodes; refused at once.
    let product = format!("r * tc * {}", vec!["exp(-g * w)"; 700].join(" * "));
    law_file(tmp.path(), "product", &product);
    let started = std::time::Instant::now();
    assert_refused(
        run_in(tmp.path(), &["law", "product.toml"]),
        &[
            "product.toml:2:",
            "derivatives could hold",
            "write a repeated factor as a power",
        ],
    );
    assert!(started.elapsed().as_secs() < 10, "{:?}", started.elapsed());
    // A sum of 600 terms compiles, quickly, to WGSL that naga accepts (the load validates it)
    // and that binds deep nesting to `let`s; its value is the sum's.
    let sum = format!("r * tc * ({})", vec!["exp(-g * w)"; 600].join(" + "));
    law_file(tmp.path(), "sum", &sum);
    let started = std::time::Instant::now();
    let law = bitrock::laws::file::LawFile::load(&tmp.path().join("sum.toml")).unwrap();
    assert!(started.elapsed().as_secs() < 10, "{:?}", started.elapsed());
    let wgsl = law.wgsl();
    assert!(wgsl.contains("let t0 = "), "{}", &wgsl[..200]);
    assert!(
        wgsl.len() < 100 * sum.len(),
        "WGSL of {} bytes for a {}-byte torque",
        wgsl.len(),
        sum.len()
    );
    let t = law.torque(&[6500.0, 0.3], 2.0, 1.0);
    let want = 6500.0 * 600.0 * (-0.6f64).exp();
    assert!((t - want).abs() <= 1e-9 * want, "{t} {want}");
    // Powers of powers are bound to `let`s, not repeated: linear text.
    law_file(tmp.path(), "powers", "r * tc * (((g * w + 1)^16 + 1)^16 + 1)^-16");
    let powers = bitrock::laws::file::LawFile::load(&tmp.path().join("powers.toml")).unwrap();
    assert!(powers.wgsl().len() < 20_000, "{}", powers.wgsl().len());
    // A constant beyond f32 is named as such, not as an internal error.
    law_file(tmp.path(), "huge", "r * tc * 1e39 * g * w");
    assert_refused(
        run_in(tmp.path(), &["law", "huge.toml"]),
        &["huge.toml:2:", "1e39 does not fit in f32"],
    );
}

#[test]
#[cfg_attr(skip_gpu_tests, ignore = "BITROCK_SKIP_GPU_TESTS=1")]
fn a_law_that_loses_digits_in_f32_is_blamed_not_the_gpu() {
    crate::gpu::require_gpu();
    let tmp = tempfile::tempdir().unwrap();
    // tc·10⁴ + cv·w − tc·10⁴: the viscous term's digits are lost in f32 beside 6.5·10⁷ N·m.
    std::fs::write(
        tmp.path().join("cancel.toml"),
        "name = \"cancel\"\ntorque = \"r * (tc * exp(-g * w) + (tc * 1e4 + cv * w) - tc * 1e4)\"\n\n\
         [[parameter]]\nname = \"tc\"\nunit = \"N·m\"\nlower = 0\n\n[[parameter]]\nname = \"g\"\nunit = \"s/rad\"\nlower = 0\n\n\
         [[parameter]]\nname = \"cv\"\nunit = \"N·m·s/rad\"\nlower = 0\n",
    )
    .unwrap();
    let args = [
        "parity",
        "--law-file",
        "cancel.toml",
        "--laws",
        "cancel,m2",
        "--candidates",
        "1000",
        "--json",
    ];
    let (code, out, err) = run_in(tmp.path(), &args);
    assert_eq!(code, 1, "a difference was found: {err}");
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    let law = |name: &str| {
        report["laws"]
            .as_array()
            .unwrap()
            .iter()
            .find(|l| l["law"] == name)
            .unwrap()
            .clone()
    };
    assert_eq!(law("cancel")["ill_conditioned_in_f32"], true, "{out}");
    assert!(law("cancel")["f32_rel_diff"].as_f64().unwrap() > bitrock::eval::PARITY_TOLERANCE);
    assert_eq!(law("m2")["ill_conditioned_in_f32"], false);
    assert!(law("m2")["f32_rel_diff"].is_null(), "built-in laws are not probed");
    assert_eq!(
        (report["pass"].clone(), report["gpu_agrees"].clone()),
        (false.into(), true.into())
    );
    let (_, text, _) = run_in(tmp.path(), &args[..args.len() - 1]);
    assert!(text.contains("law cancel: ill-conditioned in f32"), "{text}");
    assert!(!text.contains("do not trust this GPU"), "{text}");
    // A run on the GPU says so, in its warnings.
    let (code, _, err) = run_in(
        tmp.path(),
        &[
            "abc",
            "--law-file",
            "cancel.toml",
            "--laws",
            "cancel,m2",
            "--particles",
            "200",
            "--max-populations",
            "1",
            "--backend",
            "gpu",
            "--out",
            "R",
            "-q",
        ],
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        err.matches("law cancel: its torque loses digits in f32").count(),
        1,
        "{err}"
    );
}

#[test]
fn names_that_would_collide_are_refused_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    // Law x with parameter y_z and law x_y with parameter z share the store column x_y_z.
    let file = |name: &str, param: &str| {
        std::fs::write(
            tmp.path().join(format!("{name}.toml")),
            format!(
                "name = \"{name}\"\ntorque = \"r * {param}\"\n\n[[parameter]]\nname = \"{param}\"\nunit = \"N·m\"\nlower = 0\n"
            ),
        )
        .unwrap();
    };
    file("x", "y_z");
    file("x_y", "z");
    let started = std::time::Instant::now();
    assert_refused(
        run_in(
            tmp.path(),
            &[
                "abc",
                "--law-file",
                "x.toml",
                "--law-file",
                "x_y.toml",
                "--laws",
                "x,x_y,m2",
                "--out",
                "R",
                "--backend",
                "cpu",
            ],
        ),
        &["--law-file", "share the column 'x_y_z'"],
    );
    assert!(started.elapsed().as_secs() < 5, "refused before the fits");
    assert_eq!(names(tmp.path()), ["x.toml", "x_y.toml"], "nothing written");
    // A law may not take a word bitrock uses where law names go.
    file("mixture", "tc");
    assert_refused(
        run_in(tmp.path(), &["law", "mixture.toml"]),
        &["mixture.toml:1:", "a word bitrock uses in its outputs"],
    );
}

#[test]
fn exported_parameter_columns_are_named_by_their_law() {
    let tmp = tempfile::tempdir().unwrap();
    // The shipped restatement of m2 reuses m2's parameter names.
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws/navarro_suarez.toml");
    let law = bitrock::laws::file::LawFile::load(&example).unwrap();
    let (code, _, err) = small_run(
        tmp.path(),
        "R",
        &[
            "--law-file",
            example.to_str().unwrap(),
            "--laws",
            &format!("m2,{}", law.name),
        ],
    );
    assert_eq!(code, 0, "{err}");
    let (code, csv, err) = run_in(tmp.path(), &["export", "R"]);
    assert_eq!(code, 0, "{err}");
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let unique: std::collections::BTreeSet<&str> = header.iter().copied().collect();
    assert_eq!(unique.len(), header.len(), "{header:?}");
    assert!(header.contains(&"m2.tsb [kN·m]"), "{header:?}");
    assert!(
        header.iter().any(|h| h.starts_with(&format!("{}.", law.name))),
        "{header:?}"
    );
}
