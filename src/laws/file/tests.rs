use super::*;
use crate::Law;

/// The built-in laws written as law files (examples/laws).
pub(crate) fn built_in_files() -> Vec<(Law, LawFile)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
    [
        (Law::M1, "tucker_wang"),
        (Law::M2, "navarro_suarez"),
        (Law::M3, "gaussian_tanh"),
        (Law::M4, "cubic"),
    ]
    .into_iter()
    .map(|(law, file)| (law, LawFile::load(&dir.join(format!("{file}.toml"))).unwrap()))
    .collect()
}

fn parse(text: &str) -> Result<LawFile> {
    LawFile::parse(text, Path::new("law.toml"))
}

/// (line, column, message) of a refused law file.
fn refusal(text: &str) -> (u64, usize, String) {
    match parse(text).unwrap_err() {
        Error::Syntax {
            path,
            line,
            column,
            message,
        } => {
            assert_eq!(path, Path::new("law.toml"));
            (line, column, message)
        }
        other => panic!("not a syntax error: {other}"),
    }
}

#[test]
fn the_built_in_laws_as_files_give_the_built_in_torques_slopes_and_gradients() {
    for (law, file) in built_in_files() {
        // Same parameters, dimensions and bounds.
        assert_eq!(file.params.len(), law.n_params(), "{law}");
        for (spec, p) in law.params().iter().zip(&file.params) {
            assert_eq!(
                (spec.name, spec.torque_power, spec.inverse_speed_power, spec.lower),
                (p.name.as_str(), p.torque_power, p.inverse_speed_power, p.lower),
                "{law}"
            );
        }
        let reference: Vec<f64> = file.params.iter().map(|p| p.reference.unwrap()).collect();
        let paper = law.scale_torque(law.paper_estimate().unwrap(), 1000.0);
        for (a, b) in reference.iter().zip(&paper) {
            assert!(
                (a - b).abs() <= 1e-12 * b.abs(),
                "{law}: {reference:?} against {paper:?}"
            );
        }
        // Parameter sets around the paper's, at speeds from backwards through zero to fast, at
        // two ratios.
        for scale in [1.0, 0.5, 1.7] {
            let p: Vec<f64> = paper.iter().map(|v| v * scale).collect();
            for w in [-0.8, -1e-9, 0.0, 1e-9, 0.05, 0.4, 1.3, 6.0, 19.0] {
                for r in [1.0, 0.73] {
                    let close = |a: f64, b: f64, what: &str| {
                        let size = a.abs().max(b.abs()).max(1e-300);
                        assert!(
                            (a - b).abs() <= 1e-12 * size,
                            "{law} {what} at w = {w}, r = {r}, p = {p:?}: {a} against {b}"
                        );
                    };
                    close(file.torque(&p, w, r), law.torque(&p, w, r), "torque");
                    close(file.dtorque_dw(&p, w, r), law.dtorque_dw(&p, w, r), "dT/dw");
                    let n = law.n_params();
                    let (mut g_file, mut g_law) = (vec![0.0; n], vec![0.0; n]);
                    let t_file = file.torque_and_gradient(&p, w, 1.0, &mut g_file);
                    let t_law = law.torque_and_gradient(&p, w, &mut g_law);
                    close(t_file, t_law, "torque with its gradient");
                    for (a, b) in g_file.iter().zip(&g_law) {
                        close(*a, *b, "gradient");
                    }
                }
            }
        }
    }
}

#[test]
fn units_read_as_bitrock_prints_them() {
    for (text, dims) in [
        ("1", (0, 0)),
        ("N·m", (1, 0)),
        ("N*m", (1, 0)),
        ("N.m", (1, 0)),
        ("rad/s", (0, -1)),
        ("s/rad", (0, 1)),
        ("s^2/rad^2", (0, 2)),
        ("rad^2/s^2", (0, -2)),
        ("N·m·s/rad", (1, 1)),
        ("N·m·s^3 / rad^3", (1, 3)),
        ("N·m·rad/s", (1, -1)),
    ] {
        assert_eq!(parse_unit(text), Some(dims), "{text}");
    }
    for text in ["kN·m", "m/s", "", "s^4/rad^4"] {
        assert_eq!(parse_unit(text), None, "{text}");
    }
}

#[test]
fn a_refused_file_names_the_line_column_and_what_is_wrong() {
    let head = "name = \"mine\"\ntorque = \"r * (a + b * w)\"\n";
    let param = |name: &str| format!("[[parameter]]\nname = \"{name}\"\nunit = \"N·m\"\n");
    // An unknown name in the torque: the column is the name's own.
    let (line, column, message) = refusal(&format!(
        "name = \"mine\"\ntorque = \"r * (a + q * w)\"\n{}",
        param("a")
    ));
    assert_eq!((line, column), (2, 20));
    assert!(message.contains("unknown name 'q'"), "{message}");
    // A function given the wrong number of arguments, in a multi-line string.
    let (line, column, message) = refusal(&format!(
        "name = \"mine\"\ntorque = \"\"\"\nr * a *\n  exp(w, a)\"\"\"\n{}",
        param("a")
    ));
    assert_eq!((line, column), (4, 3));
    assert_eq!(message, "torque: exp takes 1 argument, got 2");
    // A parameter never used: where it is named.
    let (line, column, message) = refusal(&format!("{head}{}{}{}", param("a"), param("b"), param("c")));
    assert_eq!((line, column), (10, 8));
    assert_eq!(message, "parameter 'c' is never used in the torque");
    // A unit bitrock does not know.
    let (line, _, message) = refusal(&format!(
        "{head}{}[[parameter]]\nname = \"b\"\nunit = \"kN·m\"\n",
        param("a")
    ));
    assert_eq!(line, 8);
    assert!(message.contains("unit 'kN·m'"), "{message}");
    // TOML's own errors, an unknown key among them.
    let (line, _, message) = refusal(&format!("{head}{}colour = 3\n", param("a")));
    assert_eq!(line, 6);
    assert!(message.contains("colour"), "{message}");
    let (line, _, _) = refusal("name = \"mine\"\ntorque = \"w\n");
    assert_eq!(line, 2);
    // Names: a built-in law's, a reserved parameter name, a duplicate, a bad law name.
    assert!(refusal("name = \"m2\"\ntorque = \"w\"\n").2.contains("built-in"));
    assert!(refusal(&format!("{head}{}", param("tanh"))).2.contains("reserved"));
    assert!(
        refusal(&format!("{head}{}{}", param("a"), param("a")))
            .2
            .contains("twice")
    );
    assert!(refusal("name = \"My Law\"\ntorque = \"w\"\n").2.contains("lower-case"));
    // References below their bound; a bound of a kind that does not exist.
    let (line, _, message) = refusal(&format!(
        "{head}{}[[parameter]]\nname = \"b\"\nunit = \"1\"\nlower = 0\nreference = -1\n",
        param("a")
    ));
    assert_eq!(line, 10);
    assert!(message.contains("below its lower bound 0"), "{message}");
    let (_, _, message) = refusal(&format!(
        "{head}{}[[parameter]]\nname = \"b\"\nunit = \"1\"\nmaximum = 1\n",
        param("a")
    ));
    assert!(message.contains("maximum"), "{message}");
    // Dimensions: a sum of unlike units, a dimensioned exponential, a result not a torque, and
    // the ratio r not a factor.
    let dims = |torque: &str| {
        refusal(&format!(
            "name = \"mine\"\ntorque = \"{torque}\"\n[[parameter]]\nname = \"t\"\nunit = \"N·m\"\n[[parameter]]\nname = \"g\"\nunit = \"s/rad\"\n"
        ))
    };
    let (line, column, message) = dims("r * (t + w) * g / g");
    assert_eq!((line, column), (2, 11));
    assert!(
        message.contains("adding w to t: t is in N·m and w in rad/s"),
        "{message}"
    );
    assert!(
        dims("r * t * exp(-w) * g / g")
            .2
            .contains("the argument of exp -w has dimension rad/s")
    );
    assert!(
        dims("r * t * g")
            .2
            .contains("the expression is in N·m·s/rad, not a torque")
    );
    assert!(
        dims("t * exp(-g * w)")
            .2
            .contains("proportional to the weight-on-bit ratio")
    );
    assert!(
        dims("r * t * exp(-g * w) + t")
            .2
            .contains("proportional to the weight-on-bit ratio")
    );
    assert!(dims("r * t * (g * w)^w").2.contains("exponent"));
    assert!(parse("name = \"mine\"\ntorque = \"r * t * exp(-(g * w)^2) * sqrt(g * w)\"\n[[parameter]]\nname = \"t\"\nunit = \"N·m\"\n[[parameter]]\nname = \"g\"\nunit = \"s/rad\"\n").is_ok());
    // Too many parameters.
    let seven: String = (0..7).map(|i| param(&format!("k{i}"))).collect();
    assert!(
        refusal(&format!("name = \"mine\"\ntorque = \"w\"\n{seven}"))
            .2
            .contains("at most 6")
    );
}

#[test]
fn a_law_file_compiles_to_wgsl_that_naga_accepts() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/laws");
    let law = LawFile::load(&dir.join("stribeck.toml")).unwrap();
    assert_eq!(law.params.len(), 4);
    let text = law.wgsl();
    assert!(
        text.contains("fn file_torque_stribeck(p: array<f32, 6>, w: f32, r: f32) -> f32"),
        "{text}"
    );
    assert!(text.contains("fn file_slope_stribeck("), "{text}");
    // The source is kept whole, for a run to store.
    assert_eq!(law.source, std::fs::read_to_string(dir.join("stribeck.toml")).unwrap());
    // dT/dw of the Stribeck law at the origin is cv·r (the Gaussian is flat there).
    let p = [13_000.0, 6_500.0, 0.4, 120.0];
    assert!((law.dtorque_dw(&p, 0.0, 0.8) - 0.8 * 120.0).abs() < 1e-12);
    // T(0) = r·ts.
    assert!((law.torque(&p, 0.0, 0.8) - 0.8 * 13_000.0).abs() < 1e-9);
}

#[test]
fn a_missing_file_is_a_read_error() {
    let err = LawFile::load(Path::new("/nonexistent/law.toml")).unwrap_err();
    assert!(matches!(err, Error::Read { .. }), "{err}");
    assert!(err.is_bad_input());
}

#[test]
fn registered_laws_order_by_name_whatever_the_order_they_came_in() {
    let file = |name: &str| {
        let text = format!("name = \"{name}\"\ntorque = \"r * t\"\n[[parameter]]\nname = \"t\"\nunit = \"N·m\"\n");
        register(LawFile::parse(&text, Path::new("order.toml")).unwrap()).unwrap()
    };
    let late = file("order_zz");
    let early = file("order_aa");
    assert!(early < late && Law::M4 < early);
    // The same file again is the same law; another file of that name is refused.
    assert_eq!(file("order_zz"), late);
    let other = "name = \"order_zz\"\ntorque = \"r * t * 2\"\n[[parameter]]\nname = \"t\"\nunit = \"N·m\"\n";
    let err = register(LawFile::parse(other, Path::new("other.toml")).unwrap()).unwrap_err();
    assert!(
        err.to_string()
            .contains("two different law files define the law 'order_zz'"),
        "{err}"
    );
    assert_eq!("order_aa".parse::<Law>(), Ok(early));
}
