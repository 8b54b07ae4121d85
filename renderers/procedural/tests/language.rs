//! The scene language: every construct and function, per-sample control
//! flow, and every error a scene author can meet.

use fbksd_core::{Feature, RandomParameter};
use fbksd_procedural::program::{Machine, LANES};
use fbksd_procedural::Scene;
use std::f64::consts::{E, PI};

const HEADER: &str = "width := 10;\nheight := 10;\nspp := 4;\n#\n";

fn scene(program: &str) -> Scene {
    Scene::parse("t.expr", &format!("{HEADER}{program}")).unwrap_or_else(|e| panic!("{e}"))
}

/// Runs `program` on lanes whose IMAGE_X is the lane index; returns COLOR_R/G/B per lane.
fn run_lanes(program: &str, lanes: usize) -> Vec<[f64; 3]> {
    let scene = scene(program);
    let mut m = Machine::new(&scene.program);
    if let Some(slot) = scene.program.parameter_slot(RandomParameter::ImageX) {
        for (i, v) in m.slot_mut(slot).iter_mut().enumerate() {
            *v = i as f64;
        }
    }
    m.run(if lanes == LANES { u64::MAX } else { (1 << lanes) - 1 }).unwrap();
    let read = |f: Feature, i: usize| scene.program.feature_slot(f, 0).map_or(0.0, |s| m.slot(s)[i]);
    (0..lanes).map(|i| [read(Feature::ColorR, i), read(Feature::ColorG, i), read(Feature::ColorB, i)]).collect()
}

fn value(expr: &str) -> f64 {
    run_lanes(&format!("COLOR_R := {expr};"), 1)[0][0]
}

fn error(text: &str) -> String {
    Scene::parse("t.expr", text).unwrap_err()
}

#[track_caller]
fn close(got: f64, want: f64) {
    assert!((got - want).abs() <= 1e-12 * want.abs().max(1.0), "got {got}, want {want}");
}

#[test]
fn arithmetic_and_precedence() {
    close(value("1 + 2 * 3 - 4 / 2"), 5.0);
    close(value("2 ^ 3 ^ 2"), 512.0);
    close(value("-2 ^ 2"), -4.0);
    close(value("(1 + 2) ^ 2"), 9.0);
    close(value("2 ^ 0.5"), 2f64.sqrt());
    close(value("2 ^ 3"), 8.0);
    close(value("2 ^ -1"), 0.5);
    close(value("7 % 3"), 1.0);
    close(value("-7 % 3"), -1.0);
    close(value("+3 - -2"), 5.0);
    close(value("((1 + 2) * (3 + 4)) + ((5 + 6) * (7 + 8))"), 186.0);
    close(value("1e3 + .5 + 2.5e-1"), 1000.75);
}

#[test]
fn comparisons_and_logic() {
    close(value("(1 < 2) + (2 <= 2) + (3 > 4) + (4 >= 4) + (5 == 5) + (5 = 5) + (5 != 6) + (5 <> 5)"), 6.0);
    close(value("(1 and 0) + (1 and 2) * 2 + (0 or 0) * 4 + (0 or 3) * 8"), 10.0);
    close(value("(1 & 1) + (0 | 1) * 2"), 3.0);
    close(value("(1 xor 1) + (1 xor 0) * 2 + (1 nand 1) * 4 + (0 nor 0) * 8"), 10.0);
    close(value("not 0 + not(5) * 2"), 1.0);
    close(value("true + false + (0 / 0 ? 1 : 0)"), 2.0); // NaN is true, as in ExprTk
}

#[test]
fn every_function() {
    let cases: &[(&str, f64)] = &[
        ("sin(pi / 2)", 1.0),
        ("cos(0)", 1.0),
        ("tan(pi / 4)", 1.0),
        ("asin(1)", PI / 2.0),
        ("acos(1)", 0.0),
        ("atan(1)", PI / 4.0),
        ("atan2(1, 1)", PI / 4.0),
        ("sinh(0)", 0.0),
        ("cosh(0)", 1.0),
        ("tanh(0)", 0.0),
        ("exp(1)", E),
        ("expm1(0)", 0.0),
        ("log(exp(2))", 2.0),
        ("log1p(0)", 0.0),
        ("log2(8)", 3.0),
        ("log10(1000)", 3.0),
        ("pow(2, 10)", 1024.0),
        ("sqrt(16)", 4.0),
        ("cbrt(27)", 3.0),
        ("abs(-3)", 3.0),
        ("floor(-1.5)", -2.0),
        ("ceil(-1.5)", -1.0),
        ("round(2.5)", 3.0),
        ("round(-2.5)", -3.0),
        ("trunc(-1.7)", -1.0),
        ("frac(-1.25)", -0.25),
        ("sgn(-2) + sgn(0) * 10 + sgn(3) * 100", 99.0),
        ("min(3, 1, 2)", 1.0),
        ("max(3, 1, 2)", 3.0),
        ("min(4)", 4.0),
        ("sum(1, 2, 3)", 6.0),
        ("avg(1, 2, 6)", 3.0),
        ("clamp(0, 5, 1)", 1.0),
        ("clamp(0, -5, 1)", 0.0),
        ("inrange(0, 0.5, 1) + inrange(0, 2, 1) * 2", 1.0),
        ("hypot(3, 4)", 5.0),
        ("mod(7, 3)", 1.0),
        ("deg2rad(180)", PI),
        ("rad2deg(pi)", 180.0),
        ("erf(0) + erfc(0)", 1.0),
        ("sinc(0) + sinc(pi)", 1.0),
        ("if(1, 2, 3) + if(0, 20, 30)", 32.0),
        ("min(1 + 2, max(4, 5) * 2, avg(3, 9))", 3.0),
        ("epsilon > 0 and epsilon < 1e-15", 1.0),
    ];
    for (expr, want) in cases {
        let got = value(expr);
        assert!((got - want).abs() < 1e-9, "{expr} = {got}, want {want}");
    }
}

#[test]
fn ieee_results_of_bad_arithmetic() {
    assert_eq!(value("1 / 0"), f64::INFINITY);
    assert_eq!(value("-1 / 0"), f64::NEG_INFINITY);
    assert!(value("0 / 0").is_nan());
    assert!(value("sqrt(-1)").is_nan());
    assert!(value("log(0)").is_infinite());
    assert_eq!(value("inf"), f64::INFINITY);
}

#[test]
fn variables_arrays_and_compound_assignment() {
    let r = run_lanes("var x := 1; x += 2; x *= 3; x -= 1; x /= 2; x %= 3; COLOR_R := x;", 1);
    close(r[0][0], 1.0);
    let r = run_lanes(
        "var a[3] := {1, 2, 3}; var i := 2; var j := 7; a[1] := 10; a[j] := 99; COLOR_R := a[i] + a[1]; COLOR_G := a[j]; var b[2]; COLOR_B := b[0] + b[1];",
        1,
    );
    close(r[0][0], 13.0);
    assert!(r[0][1].is_nan(), "reading outside an array gives NaN");
    close(r[0][2], 0.0);
    // Reading a feature before assigning it gives 0; features can be read back.
    let r = run_lanes("COLOR_R := DEPTH + 1; COLOR_G := COLOR_R * 2;", 1);
    assert_eq!(r[0][..2], [1.0, 2.0]);
    // Width, height and spp come from the header.
    close(value("width * 100 + height * 10 + spp"), 1104.0);
}

#[test]
fn control_flow_is_per_sample() {
    // Lane k has IMAGE_X = k.
    let r =
        run_lanes("if (IMAGE_X < 3) COLOR_R := 1; else if (IMAGE_X < 5) { COLOR_R := 2 } else { COLOR_R := 3 };", 8);
    assert_eq!(r.iter().map(|v| v[0]).collect::<Vec<_>>(), [1.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 3.0]);
    // A while loop with a per-lane trip count and a break.
    let r = run_lanes("var i := 0; while (i < IMAGE_X) { i += 1; if (i == 5) break; }; COLOR_R := i;", 8);
    assert_eq!(r.iter().map(|v| v[0]).collect::<Vec<_>>(), [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 5.0, 5.0]);
    // for with continue: sum of odd numbers below IMAGE_X.
    let r = run_lanes(
        "var s := 0; for (var i := 0; i < IMAGE_X; i += 1) { if (i % 2 == 0) continue; s += i; }; COLOR_R := s;",
        8,
    );
    assert_eq!(r.iter().map(|v| v[0]).collect::<Vec<_>>(), [0.0, 0.0, 1.0, 1.0, 4.0, 4.0, 9.0, 9.0]);
    // A ternary's branches run only for their own samples (they may assign).
    let r = run_lanes("var y := 0; COLOR_R := IMAGE_X > 2 ? (y := 5) : (y := 7); COLOR_G := y;", 5);
    assert_eq!(
        r.iter().map(|v| (v[0], v[1])).collect::<Vec<_>>(),
        [(7.0, 7.0), (7.0, 7.0), (7.0, 7.0), (5.0, 5.0), (5.0, 5.0)]
    );
    // Nested loops.
    let r = run_lanes("var n := 0; for (var i := 0; i < 3; i += 1) { for (var j := 0; j < IMAGE_X; j += 1) { n += 1 } }; COLOR_R := n;", 4);
    assert_eq!(r.iter().map(|v| v[0]).collect::<Vec<_>>(), [0.0, 3.0, 6.0, 9.0]);
    // Every one of the 64 lanes, with a partial batch too.
    let r = run_lanes("COLOR_R := IMAGE_X * 2;", 37);
    assert!(r.iter().enumerate().all(|(i, v)| v[0] == 2.0 * i as f64));
}

#[test]
fn numbered_and_ns_features_are_names_in_scenes() {
    let s = scene("WORLD_X_1 := 3; NORMAL_Z_NS := 4; TEXTURE_COLOR_B_1 := 5;");
    let mut m = Machine::new(&s.program);
    m.run(1).unwrap();
    let get = |f, n| m.slot(s.program.feature_slot(f, n).unwrap())[0];
    assert_eq!((get(Feature::WorldX, 1), get(Feature::NormalZNs, 0), get(Feature::TextureColorB, 1)), (3.0, 4.0, 5.0));
}

#[test]
fn a_layout_computes_only_what_it_asks() {
    let s =
        scene("var a := IMAGE_X * 2; var b := a + 1; var c := IMAGE_Y; COLOR_R := b; DEPTH := c; COLOR_G := COLOR_R;");
    assert_eq!(s.program.statement_count(), 6);
    assert_eq!(s.program.specialise(&[(Feature::Depth, 0)]).statement_count(), 2, "var c and DEPTH");
    assert_eq!(s.program.specialise(&[(Feature::ColorG, 0)]).statement_count(), 4, "a, b, COLOR_R, COLOR_G");
    assert_eq!(s.program.specialise(&[(Feature::NormalX, 0)]).statement_count(), 0);
    // Inside if branches too: DEPTH is not computed when only colour is asked.
    let s = scene("if (IMAGE_X > 1) { COLOR_R := 1; DEPTH := 2 } else { var d := 3; DEPTH := d; COLOR_R := 4 };");
    assert_eq!(s.program.statement_count(), 6);
    assert_eq!(s.program.specialise(&[(Feature::ColorR, 0)]).statement_count(), 3, "the if and one store per branch");
    assert_eq!(s.program.specialise(&[(Feature::Depth, 0)]).statement_count(), 4, "the if, DEPTH, var d, DEPTH");
    let r = run_lanes("if (IMAGE_X > 1) { COLOR_R := 1; DEPTH := 2 } else { COLOR_R := 4 };", 3);
    assert_eq!(r.iter().map(|v| v[0]).collect::<Vec<_>>(), [4.0, 4.0, 1.0]);
}

#[test]
fn syntax_errors_name_line_column_and_text() {
    let e = error("width := 4;\nheight := 4;\n#\nvar x := (1 + 2;\n");
    assert_eq!(e, "t.expr:4:16: expected ')' but found ';'\n    var x := (1 + 2;\n                   ^");
    let cases: &[(&str, &str)] = &[
        ("COLOR_R := foo;", "t.expr:5:12: unknown name 'foo'"),
        ("COLOR_R := sine(1);", "t.expr:5:12: unknown function 'sine' (known: abs, acos,"),
        ("COLOR_R := atan2(1);", "atan2() takes 2 arguments, got 1"),
        ("COLOR_R := sin(1, 2);", "sin() takes 1 argument, got 2"),
        ("IMAGE_X := 1;", "IMAGE_X is a random parameter: it can be read, not assigned"),
        ("width := 3;", "'width' is a constant"),
        ("var a[2]; COLOR_R := a;", "'a' is an array: index it"),
        ("var a[2]; COLOR_R := a[2];", "index 2 is outside 'a' (size 2)"),
        ("var a[2]; a[-1] := 2;", "index -1 is outside 'a' (size 2)"),
        ("var x := 1; var x := 2;", "'x' is already declared in this scope"),
        ("break;", "'break' and 'continue' belong inside a loop"),
        ("var x := 1 +;", "expected a value but found ';'"),
        ("COLOR_R := 1 $ 2;", "unexpected character '$'"),
        ("var a[2] := {1, 2, 3};", "array 'a' has 2 elements but 3 initial values"),
        ("var TIME := 1;", "'TIME' is a random parameter or feature name"),
        ("else COLOR_R := 1;", "'else' without 'if'"),
        ("/* unterminated", "unterminated comment"),
    ];
    for (program, want) in cases {
        let e = error(&format!("{HEADER}{program}"));
        assert!(e.contains(want), "{program:?}: {e}");
    }
}

#[test]
fn header_errors() {
    assert!(error("width := 4; height := 4;\nCOLOR_R := 1;").contains("no line holding only '#'"));
    assert!(error("height := 4;\n#\nCOLOR_R := 1;").contains("the header must set 'width'"));
    assert!(error("width := 4.5; height := 4;\n#\n").contains("t.expr:1:7: 'width' must be a whole number"));
    assert!(error("width := 4; height := 4; depth := 3;\n#\n").contains("t.expr:1:26: unknown header key 'depth'"));
    assert!(error("width[0] := 5; height := 4;\n#\n").contains("t.expr:1:10: the header assigns plain names"));
    assert!(error("width := 4;\nheight = 4;\n#\n").contains("t.expr:2:1: the header holds only assignments"));
    let s = Scene::parse("t", "width := 2^9; height := 100 * 3;\n#\nCOLOR_R := 1;").unwrap();
    assert_eq!((s.width, s.height, s.spp), (512, 300, 64));
}

#[test]
fn an_endless_loop_is_a_runtime_error_with_its_position() {
    let s = scene("var i := 0;\nwhile (i >= 0) { i += 1 };\nCOLOR_R := i;");
    let e = Machine::new(&s.program).run(1).unwrap_err();
    assert_eq!(
        s.runtime_error(e.pos, &e.message).lines().next().unwrap(),
        "t.expr:6:1: loop ran more than 10000000 times (endless loop?)"
    );
}

#[test]
fn scene_info_reports_what_the_program_uses() {
    let info = scene("COLOR_R := LENS_U;").info();
    assert_eq!(info.get::<bool>("has_dof"), Ok(true));
    assert_eq!(info.get::<bool>("has_motion_blur"), Ok(false));
    assert_eq!(info.get::<String>("random_parameters").unwrap(), "LENS_U");
    let info = scene("COLOR_R := TIME + IMAGE_X;").info();
    assert_eq!(info.get::<bool>("has_dof"), Ok(false));
    assert_eq!(info.get::<bool>("has_motion_blur"), Ok(true));
    assert_eq!(info.get::<i64>("width"), Ok(10));
}

/// Regression: an element assignment's value lived in a temporary that the
/// right-hand operand then reused (`X + 1` came out as `2X`).
#[test]
fn an_element_assignment_keeps_its_value_inside_an_expression() {
    let r = run_lanes("var a[1]; COLOR_R := (a[0] := IMAGE_X + 1) + (IMAGE_X * 2 + 3); COLOR_G := a[0];", 4);
    assert_eq!(r.iter().map(|v| (v[0], v[1])).collect::<Vec<_>>(), [(4.0, 1.0), (7.0, 2.0), (10.0, 3.0), (13.0, 4.0)]);
}

/// Regression: the ternary re-read its condition after a branch had
/// assigned to it, and picked the wrong branch for those samples.
#[test]
fn a_branch_that_assigns_its_condition_still_selects_by_the_old_value() {
    let r = run_lanes("var h := IMAGE_X > 2; COLOR_R := h ? (h := 0) : 5; COLOR_G := h;", 5);
    assert_eq!(
        r.iter().map(|v| (v[0], v[1])).collect::<Vec<_>>(),
        [(5.0, 0.0), (5.0, 0.0), (5.0, 0.0), (0.0, 0.0), (0.0, 0.0)]
    );
}

/// Assignments are values, taken in left-to-right order as in ExprTk.
#[test]
fn assignments_used_as_values_are_taken_in_order() {
    let r = run_lanes("var x := 0; COLOR_R := (x := 2) + (x := 3); COLOR_G := x;", 1);
    assert_eq!(r[0][..2], [5.0, 3.0]);
}
