//! `.mymaterial` files: the `Material` structures of an OpenDDL file turned into material
//! definitions (texture references, constants), with warnings for what is ignored.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::diagnostic::{Diagnostic, TextPosition};
use crate::openddl::{self, Structure, StructureBody, Value};
use crate::texture::TextureSlot;
use base::paths::normalize_relative_path;

/// The slot a `Texture (attrib = "…")` fills.
fn slot_from_attrib(attrib: &str) -> Option<TextureSlot> {
    Some(match attrib {
        "diffuse" | "albedo" | "base_color" => TextureSlot::Albedo,
        "opacity" | "transparency" | "alpha" => TextureSlot::Opacity,
        "normal" => TextureSlot::Normal,
        "metallic" | "metalness" => TextureSlot::Metallic,
        "roughness" => TextureSlot::Roughness,
        "ao" | "occlusion" => TextureSlot::Ao,
        _ => return None,
    })
}

/// A texture path as written, and where it resolves inside the source folder.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct TextureReference {
    /// Relative to the source folder.
    pub path: PathBuf,
    pub written: String,
    pub position: TextPosition,
}

/// Constant values used where a map is missing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MaterialConstants {
    /// `Color (attrib = "diffuse")`, used as albedo when there is no albedo map.
    pub albedo: [f32; 4],
    pub metallic: f32,
    pub roughness: f32,
    pub ao: f32,
    /// `Param (attrib = "alpha_cutoff")`; otherwise the asset's `billboard.alpha_cutoff`.
    pub alpha_cutoff: Option<f32>,
}

impl MaterialConstants {
    /// What the packed surfaces take where a map is missing.
    pub fn pack_constants(&self) -> crate::texture::channel_packing::PackConstants {
        let MaterialConstants { albedo, metallic, roughness, ao, .. } = *self;
        crate::texture::channel_packing::PackConstants { albedo, metallic, roughness, ao }
    }
}

impl Default for MaterialConstants {
    fn default() -> Self {
        MaterialConstants { albedo: [1.0; 4], metallic: 0.0, roughness: 1.0, ao: 1.0, alpha_cutoff: None }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MaterialDefinition {
    /// The structure name without `$` or `%`: the material's output folder.
    pub name: String,
    pub display_name: Option<String>,
    pub position: TextPosition,
    pub textures: BTreeMap<TextureSlot, TextureReference>,
    pub constants: MaterialConstants,
}

/// Everything one `.mymaterial` file defines.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MaterialFile {
    pub materials: Vec<MaterialDefinition>,
    pub warnings: Vec<Diagnostic>,
}

/// Parses the bytes of the `.mymaterial` at `file`; texture paths resolve relative to it and must
/// stay inside `source_root` (both relative to the project folder).
pub fn parse_material_file(file: &Path, bytes: &[u8], source_root: &Path) -> Result<MaterialFile, Diagnostic> {
    let text = std::str::from_utf8(bytes).map_err(|error| {
        let position =
            TextPosition::of_byte_offset(&String::from_utf8_lossy(&bytes[..error.valid_up_to()]), error.valid_up_to());
        Diagnostic::at(file, position, "the file is not valid UTF-8 text")
    })?;
    let structures = openddl::parse(text).map_err(|error| Diagnostic::at(file, error.position, error.message))?;
    let mut reader = Reader { file, source_root, warnings: Vec::new() };
    let mut materials: Vec<MaterialDefinition> = Vec::new();
    for structure in &structures {
        match &structure.body {
            StructureBody::Custom { identifier, .. } if identifier == "Material" => {
                let material = reader.material(structure, materials.len())?;
                if let Some(first) = materials.iter().find(|other| other.name == material.name) {
                    return Err(Diagnostic::at(
                        file,
                        material.position,
                        format!("material name `{}` is already used at line {}", material.name, first.position.line),
                    ));
                }
                materials.push(material);
            }
            _ => reader.warn(
                structure.position,
                format!("`{}` structure ignored: only `Material` is read at the top level", structure.identifier()),
            ),
        }
    }
    if materials.is_empty() {
        return Err(Diagnostic::new(file, "no `Material` structure in the file"));
    }
    Ok(MaterialFile { materials, warnings: reader.warnings })
}

struct Reader<'a> {
    file: &'a Path,
    source_root: &'a Path,
    warnings: Vec<Diagnostic>,
}

impl Reader<'_> {
    fn warn(&mut self, position: TextPosition, message: String) {
        self.warnings.push(Diagnostic::at(self.file, position, message));
    }

    fn error(&self, position: TextPosition, message: impl Into<String>) -> Diagnostic {
        Diagnostic::at(self.file, position, message)
    }

    fn material(&mut self, structure: &Structure, index: usize) -> Result<MaterialDefinition, Diagnostic> {
        let name = match &structure.name {
            Some(name) => name.identifier.clone(),
            None => format!("material{index}"),
        };
        let mut material = MaterialDefinition {
            name,
            display_name: None,
            position: structure.position,
            textures: BTreeMap::new(),
            constants: MaterialConstants::default(),
        };
        for child in structure.children() {
            let identifier = child.identifier();
            match identifier.as_str() {
                "Name" => material.display_name = Some(self.string_data(child)?.0),
                "Texture" => {
                    let Some(attrib) = self.attrib(child)? else {
                        continue;
                    };
                    let Some(slot) = slot_from_attrib(&attrib) else {
                        self.warn(child.position, format!("texture attrib \"{attrib}\" is not used by the PBR baker"));
                        continue;
                    };
                    let (written, position) = self.string_data(child)?;
                    let path = self.resolve(&written, position)?;
                    if material.textures.contains_key(&slot) {
                        self.warn(child.position, format!("a second \"{attrib}\" texture replaces the first"));
                    }
                    material.textures.insert(slot, TextureReference { path, written, position });
                }
                "Color" => {
                    let Some(attrib) = self.attrib(child)? else {
                        continue;
                    };
                    let values = self.float_data(child, &[3, 4])?;
                    if matches!(attrib.as_str(), "diffuse" | "albedo" | "base_color") {
                        let alpha = values.get(3).copied().unwrap_or(1.0);
                        material.constants.albedo = [values[0], values[1], values[2], alpha];
                    } else {
                        self.warn(child.position, format!("color attrib \"{attrib}\" is not used by the PBR baker"));
                    }
                }
                "Param" => {
                    let Some(attrib) = self.attrib(child)? else {
                        continue;
                    };
                    let value = self.float_data(child, &[1])?[0];
                    let target = match attrib.as_str() {
                        "metallic" | "metalness" => &mut material.constants.metallic,
                        "roughness" => &mut material.constants.roughness,
                        "ao" | "occlusion" => &mut material.constants.ao,
                        "alpha_cutoff" => {
                            material.constants.alpha_cutoff = Some(value.clamp(0.0, 1.0));
                            continue;
                        }
                        _ => {
                            self.warn(
                                child.position,
                                format!("param attrib \"{attrib}\" is not used by the PBR baker"),
                            );
                            continue;
                        }
                    };
                    *target = value.clamp(0.0, 1.0);
                }
                other => self.warn(child.position, format!("`{other}` structure ignored inside `Material`")),
            }
        }
        Ok(material)
    }

    fn attrib(&mut self, structure: &Structure) -> Result<Option<String>, Diagnostic> {
        let identifier = structure.identifier();
        match structure.property("attrib") {
            Some(property) => match &property.value {
                Value::String(text) => Ok(Some(text.clone())),
                other => Err(self.error(
                    property.position,
                    format!("the `attrib` of `{identifier}` must be a string, found {}", other.describe()),
                )),
            },
            None => {
                self.warn(structure.position, format!("`{identifier}` without an `attrib` property ignored"));
                Ok(None)
            }
        }
    }

    /// The single primitive child of `structure`, which must hold data of `expected` type.
    fn data<'s>(
        &self,
        structure: &'s Structure,
        expected: &str,
    ) -> Result<(&'s [Value], Option<u32>, TextPosition), Diagnostic> {
        let identifier = structure.identifier();
        let mut primitives = structure.children().iter().filter_map(|child| match &child.body {
            StructureBody::Primitive { data_type, array_size, values } => Some((child, data_type, array_size, values)),
            StructureBody::Custom { .. } => None,
        });
        match primitives.next() {
            Some((child, data_type, array_size, values)) => {
                let type_ok = match expected {
                    "string" => *data_type == openddl::DataType::String,
                    _ => matches!(
                        data_type,
                        openddl::DataType::Half | openddl::DataType::Float | openddl::DataType::Double
                    ),
                };
                if !type_ok {
                    return Err(self
                        .error(child.position, format!("`{identifier}` expects {expected} data, found {data_type}")));
                }
                Ok((values, *array_size, child.position))
            }
            None => Err(self.error(structure.position, format!("`{identifier}` holds no {expected} data"))),
        }
    }

    fn string_data(&self, structure: &Structure) -> Result<(String, TextPosition), Diagnostic> {
        let (values, _, position) = self.data(structure, "string")?;
        match values {
            [Value::String(text)] => Ok((text.clone(), position)),
            _ => Err(self.error(
                position,
                format!("`{}` expects exactly one string, found {}", structure.identifier(), values.len()),
            )),
        }
    }

    fn float_data(&self, structure: &Structure, counts: &[usize]) -> Result<Vec<f32>, Diagnostic> {
        let (values, _, position) = self.data(structure, "float")?;
        let floats: Vec<f32> = values.iter().filter_map(Value::as_f64).map(|value| value as f32).collect();
        if !counts.contains(&floats.len()) {
            let expected = counts.iter().map(ToString::to_string).collect::<Vec<_>>().join(" or ");
            return Err(self.error(
                position,
                format!("`{}` expects {expected} float values, found {}", structure.identifier(), floats.len()),
            ));
        }
        if floats.iter().any(|value| !value.is_finite()) {
            return Err(self.error(position, format!("`{}` holds a value that is not finite", structure.identifier())));
        }
        Ok(floats)
    }

    /// A texture path relative to the `.mymaterial` file, resolved inside the source folder.
    fn resolve(&self, written: &str, position: TextPosition) -> Result<PathBuf, Diagnostic> {
        let folder = self.file.parent().unwrap_or(Path::new(""));
        let joined = folder.join(written.replace('\\', "/"));
        match normalize_relative_path(&joined) {
            Some(path) if path.starts_with(self.source_root) && path != self.source_root => Ok(path),
            _ => Err(self.error(
                position,
                format!("texture path \"{written}\" must be relative and stay inside the source folder"),
            )),
        }
    }
}
