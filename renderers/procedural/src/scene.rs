//! Scene files: a header of constants, a line holding only `#`, a program.
//!
//! ```text
//! width := 500;
//! height := 500;
//! spp := 64;
//! #
//! COLOR_R := IMAGE_X / width; …
//! ```
//!
//! The header sets `width` and `height` (required, whole numbers ≥ 1) and
//! `spp` (optional, default 64: the scene's nominal sample count); the
//! program reads them as read-only constants.

use crate::program::Program;
use crate::syntax::{parse_program, BinOp, Expr, Pos, SourceError, Stmt};
use fbksd_core::{RandomParameter, SceneInfo};
use std::path::Path;

/// A loaded scene.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Name for messages (the file name).
    pub name: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The header's nominal spp.
    pub spp: u32,
    /// The compiled program.
    pub program: Program,
    /// The source, for error messages.
    pub source: String,
}

impl Scene {
    /// Reads and compiles a scene file.
    pub fn load(path: &Path) -> Result<Scene, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Scene::parse(&path.display().to_string(), &text)
    }

    /// Compiles scene text; errors are `name:line:col: message` with the line and a caret.
    pub fn parse(name: &str, text: &str) -> Result<Scene, String> {
        let render = |e: SourceError| e.render(name, text);
        let mut offset = 0;
        let mut split = None;
        for (i, line) in text.split_inclusive('\n').enumerate() {
            if line.trim() == "#" {
                split = Some((i, offset, offset + line.len()));
                break;
            }
            offset += line.len();
        }
        let Some((hash_line, header_end, program_start)) = split else {
            return Err(format!(
                "{name}: no line holding only '#' separates the header (width, height, spp) from the program"
            ));
        };
        let origin = Pos { line: 1, col: 1, offset: 0 };
        let header = parse_program(&text[..header_end], origin).map_err(render)?;
        let (mut width, mut height, mut spp) = (None, None, 64u32);
        for stmt in &header {
            let Stmt::Expr(Expr::Assign { target, op: None, value, pos }) = stmt else {
                let at = header_position(stmt).unwrap_or(origin);
                return Err(render(SourceError::new(at, "the header holds only assignments like 'width := 512;'")));
            };
            let Expr::Name(key, kpos) = &**target else {
                return Err(render(SourceError::new(*pos, "the header assigns plain names: width, height, spp")));
            };
            let v = constant(value)
                .ok_or_else(|| render(SourceError::new(*pos, format!("'{key}' must be a constant number"))))?;
            let whole = |v: f64| -> Result<u32, String> {
                if v >= 1.0 && v.fract() == 0.0 && v <= 1e5 {
                    Ok(v as u32)
                } else {
                    Err(render(SourceError::new(
                        *pos,
                        format!("'{key}' must be a whole number from 1 to 100000, got {v}"),
                    )))
                }
            };
            match key.as_str() {
                "width" => width = Some(whole(v)?),
                "height" => height = Some(whole(v)?),
                "spp" => spp = whole(v)?,
                _ => {
                    return Err(render(SourceError::new(
                        *kpos,
                        format!("unknown header key '{key}' (width, height, spp)"),
                    )))
                }
            }
        }
        let missing = |k: &str| format!("{name}: the header must set '{k}'");
        let (width, height) = (width.ok_or_else(|| missing("width"))?, height.ok_or_else(|| missing("height"))?);
        let start = Pos { line: hash_line as u32 + 2, col: 1, offset: program_start };
        let stmts = parse_program(&text[program_start..], start).map_err(render)?;
        let program =
            Program::compile(&stmts, &[("width", width as f64), ("height", height as f64), ("spp", spp as f64)])
                .map_err(render)?;
        Ok(Scene { name: name.to_string(), width, height, spp, program, source: text.to_string() })
    }

    /// The scene info: size, effects the program really has, parameters it reads.
    pub fn info(&self) -> SceneInfo {
        use RandomParameter::*;
        let uses = |p| self.program.uses(p);
        let used: Vec<&str> = RandomParameter::ALL.iter().filter(|p| uses(**p)).map(|p| p.name()).collect();
        let mut info = SceneInfo::new();
        info.set("width", self.width)
            .set("height", self.height)
            .set("has_dof", uses(LensU) || uses(LensV))
            .set("has_motion_blur", uses(Time))
            .set("shutter_open", 0.0)
            .set("shutter_close", 1.0)
            .set("random_parameters", used.join(","))
            .set("renderer", "procedural");
        info
    }

    /// A runtime error rendered with this scene's source.
    pub fn runtime_error(&self, pos: Pos, message: &str) -> String {
        SourceError::new(pos, message).render(&self.name, &self.source)
    }
}

/// Where a header statement that is not an assignment starts, if known.
fn header_position(stmt: &Stmt) -> Option<Pos> {
    match stmt {
        Stmt::Var { pos, .. } | Stmt::While { pos, .. } | Stmt::Break(pos) | Stmt::Continue(pos) => Some(*pos),
        Stmt::Expr(e) => expr_position(e),
        Stmt::If { cond, .. } => expr_position(cond),
        Stmt::Block(b) => b.first().and_then(header_position),
    }
}

fn expr_position(e: &Expr) -> Option<Pos> {
    match e {
        Expr::Name(_, p) | Expr::Index(_, _, p) | Expr::Call(_, _, p) => Some(*p),
        Expr::Assign { pos, .. } => Some(*pos),
        Expr::Neg(a) | Expr::Not(a) => expr_position(a),
        Expr::Binary(_, a, _) | Expr::Ternary(a, _, _) => expr_position(a),
        Expr::Num(_) => None,
    }
}

fn constant(e: &Expr) -> Option<f64> {
    Some(match e {
        Expr::Num(n) => *n,
        Expr::Neg(a) => -constant(a)?,
        Expr::Binary(op, a, b) => {
            let (a, b) = (constant(a)?, constant(b)?);
            match op {
                BinOp::Add => a + b,
                BinOp::Sub => a - b,
                BinOp::Mul => a * b,
                BinOp::Div => a / b,
                BinOp::Pow => a.powf(b),
                _ => return None,
            }
        }
        _ => return None,
    })
}
