//! PLY meshes (ASCII and binary little/big endian) for `plymesh`: vertex
//! positions, optional normals and texture coordinates, and polygon faces
//! (fanned into triangles).

use crate::math::{vec3, Vec3};
use std::path::Path;

/// A mesh read from a PLY file.
#[derive(Debug, Default)]
pub struct PlyMesh {
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Normals, when every vertex has one.
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates, when every vertex has them.
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Triangles.
    pub indices: Vec<[u32; 3]>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    BinaryLittle,
    BinaryBig,
}

#[derive(Debug, Clone, Copy)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// Reads values one at a time from the body, in the file's format.
struct Body<'a> {
    data: &'a [u8],
    pos: usize,
    format: Format,
}

impl Body<'_> {
    fn read(&mut self, s: Scalar) -> Result<f64, String> {
        if self.format == Format::Ascii {
            while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            let start = self.pos;
            while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
                self.pos += 1;
            }
            let text = std::str::from_utf8(&self.data[start..self.pos]).map_err(|_| "invalid text".to_string())?;
            return text.parse().map_err(|_| format!("{text:?} is not a number"));
        }
        let n = s.size();
        let bytes = self.data.get(self.pos..self.pos + n).ok_or("file ends early")?;
        self.pos += n;
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(bytes);
        if self.format == Format::BinaryBig {
            b[..n].reverse();
        }
        Ok(match s {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(b),
        })
    }
}

/// Reads a PLY file.
pub fn read(path: &Path) -> Result<PlyMesh, String> {
    let data = super::read_file(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse(&data).map_err(|e| format!("{}: {e}", path.display()))
}

/// Parses PLY data.
pub fn parse(data: &[u8]) -> Result<PlyMesh, String> {
    let header_end = data.windows(11).position(|w| w == b"end_header\n").ok_or("no end_header line")? + 11;
    let header = std::str::from_utf8(&data[..header_end]).map_err(|_| "header is not text")?;
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err("not a PLY file (first line is not \"ply\")".into());
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["format", "ascii", _] => format = Some(Format::Ascii),
            ["format", "binary_little_endian", _] => format = Some(Format::BinaryLittle),
            ["format", "binary_big_endian", _] => format = Some(Format::BinaryBig),
            ["comment", ..] | ["obj_info", ..] | ["end_header"] | [] => {}
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count.parse().map_err(|_| format!("bad element count {count:?}"))?,
                properties: Vec::new(),
            }),
            ["property", "list", count, item, name] => {
                let e = elements.last_mut().ok_or("property before any element")?;
                let (c, i) = (Scalar::parse(count), Scalar::parse(item));
                e.properties.push(Property::List(
                    name.to_string(),
                    c.ok_or("bad list type")?,
                    i.ok_or("bad list type")?,
                ));
            }
            ["property", ty, name] => {
                let e = elements.last_mut().ok_or("property before any element")?;
                e.properties
                    .push(Property::Scalar(name.to_string(), Scalar::parse(ty).ok_or(format!("unknown type {ty:?}"))?));
            }
            _ => return Err(format!("unsupported header line {line:?}")),
        }
    }
    let mut body = Body { data: &data[header_end..], pos: 0, format: format.ok_or("no format line")? };
    let mut mesh = PlyMesh::default();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for element in &elements {
        let has = |n: &str| element.properties.iter().any(|p| matches!(p, Property::Scalar(m, _) if m == n));
        let with_normals = has("nx") && has("ny") && has("nz");
        let uv_names = if has("u") && has("v") {
            Some(("u", "v"))
        } else if has("s") && has("t") {
            Some(("s", "t"))
        } else if has("texture_u") && has("texture_v") {
            Some(("texture_u", "texture_v"))
        } else {
            None
        };
        for _ in 0..element.count {
            let mut vals: [f64; 8] = [0.0; 8]; // x y z nx ny nz u v
            for p in &element.properties {
                match p {
                    Property::Scalar(name, s) => {
                        let v = body.read(*s)?;
                        let slot = match name.as_str() {
                            "x" => Some(0),
                            "y" => Some(1),
                            "z" => Some(2),
                            "nx" => Some(3),
                            "ny" => Some(4),
                            "nz" => Some(5),
                            n if uv_names.is_some_and(|(u, _)| u == n) => Some(6),
                            n if uv_names.is_some_and(|(_, v)| v == n) => Some(7),
                            _ => None,
                        };
                        if let Some(i) = slot {
                            vals[i] = v;
                        }
                    }
                    Property::List(name, count, item) => {
                        let n = body.read(*count)? as usize;
                        let items: Vec<f64> = (0..n).map(|_| body.read(*item)).collect::<Result<_, _>>()?;
                        if element.name == "face" && (name == "vertex_indices" || name == "vertex_index") {
                            if n < 3 {
                                return Err(format!("a face with {n} vertices"));
                            }
                            for k in 1..n - 1 {
                                mesh.indices.push([items[0] as u32, items[k] as u32, items[k + 1] as u32]);
                            }
                        }
                    }
                }
            }
            if element.name == "vertex" {
                mesh.positions.push(vec3(vals[0] as f32, vals[1] as f32, vals[2] as f32));
                if with_normals {
                    normals.push(vec3(vals[3] as f32, vals[4] as f32, vals[5] as f32));
                }
                if uv_names.is_some() {
                    uvs.push([vals[6] as f32, vals[7] as f32]);
                }
            }
        }
    }
    if mesh.positions.is_empty() || mesh.indices.is_empty() {
        return Err("no vertices or no faces".into());
    }
    if let Some(bad) = mesh.indices.iter().flatten().find(|i| **i as usize >= mesh.positions.len()) {
        return Err(format!("face index {bad} out of range ({} vertices)", mesh.positions.len()));
    }
    mesh.normals = (!normals.is_empty()).then_some(normals);
    mesh.uvs = (!uvs.is_empty()).then_some(uvs);
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_and_binary_quads_become_two_triangles() {
        let ascii = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";
        let m = parse(ascii).unwrap();
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.uvs.unwrap()[2], [1.0, 1.0]);
        let mut binary = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
        for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
            binary.extend(v.to_le_bytes());
        }
        binary.push(3);
        for i in [0u32, 1, 2] {
            binary.extend(i.to_le_bytes());
        }
        let m = parse(&binary).unwrap();
        assert_eq!(m.positions[1], vec3(1.0, 0.0, 0.0));
        assert!(m.normals.is_none());
        binary.truncate(binary.len() - 2);
        assert!(parse(&binary).unwrap_err().contains("ends early"));
    }
}
