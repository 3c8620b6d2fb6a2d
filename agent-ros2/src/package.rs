//! The ROS 2 package of a bridge's own messages: what a ROS user builds
//! (`colcon build`) so that ROS 2 tools decode and publish the messages made
//! from buffer types (Rex's `rex_msgs`), with the same definitions, so the
//! same type hashes, as the bridge announces.
//!
//! ```
//! use agent_ros2::package::{Package, PackageError};
//! use agent_ros2::types::{Field, FieldType, Message, Messages, MsgName, Primitive};
//!
//! let ack = Message::new(
//!     MsgName::new("demo_msgs", "Ack"),
//!     vec![Field::new("id", FieldType::primitive(Primitive::Uint32))],
//! );
//! let messages = Messages { root: ack, referenced: Vec::new() };
//! let package = Package::of("demo_msgs", [&messages])?;
//! let files = package.files();
//! let paths: Vec<&str> = files.iter().map(|(path, _)| path.as_str()).collect();
//! assert_eq!(paths, ["msg/Ack.msg", "package.xml", "CMakeLists.txt"]);
//! assert_eq!(files[0].1, "uint32 id\n");
//! # Ok::<(), PackageError>(())
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use crate::types::{Message, Messages, MsgName};

/// Why a package could not be made or written.
#[derive(Debug, thiserror::Error)]
pub enum PackageError {
    /// Two definitions of one message name (a plan interns its messages, so
    /// this is messages of different plans put together).
    #[error("two different definitions of `{0}`")]
    Conflict(String),
    /// None of the messages is of the package.
    #[error("no message of package `{0}`: nothing to build")]
    Empty(String),
    /// A file could not be written.
    #[error("writing {path}: {source}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// The OS's reason.
        source: std::io::Error,
    },
}

/// The files of a ROS 2 interface package (see the module's documentation).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Package {
    name: String,
    messages: BTreeMap<String, Message>,
    depends: Vec<String>,
}

impl Package {
    /// The package `name` of the messages among `messages` (each with the
    /// messages it uses) that belong to it; the packages of the others it
    /// uses (`builtin_interfaces`, `geometry_msgs`...) are its dependencies.
    pub fn of<'m>(
        name: &str,
        messages: impl IntoIterator<Item = &'m Messages>,
    ) -> Result<Package, PackageError> {
        let mut own: BTreeMap<String, Message> = BTreeMap::new();
        let mut depends: Vec<String> = Vec::new();
        for set in messages {
            for m in std::iter::once(&set.root).chain(&set.referenced) {
                if m.name.package != name {
                    continue;
                }
                match own.get(&m.name.name) {
                    Some(known) if known != m => {
                        return Err(PackageError::Conflict(m.name.to_string()));
                    }
                    Some(_) => {}
                    None => {
                        own.insert(m.name.name.clone(), m.clone());
                    }
                }
            }
        }
        if own.is_empty() {
            return Err(PackageError::Empty(name.to_owned()));
        }
        for m in own.values() {
            for used in m.uses() {
                let MsgName { package, .. } = used;
                if package != name && !depends.contains(package) {
                    depends.push(package.clone());
                }
            }
        }
        depends.sort();
        Ok(Package {
            name: name.to_owned(),
            messages: own,
            depends,
        })
    }

    /// The package's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The packages its messages use.
    pub fn depends(&self) -> &[String] {
        &self.depends
    }

    /// Its files, relative to the package's folder: `msg/<Name>.msg` per
    /// message (in order of name), `package.xml` (format 3, a member of
    /// `rosidl_interface_packages`) and `CMakeLists.txt`
    /// (`rosidl_generate_interfaces`).
    pub fn files(&self) -> Vec<(String, String)> {
        let mut files: Vec<(String, String)> = self
            .messages
            .iter()
            .map(|(name, m)| (format!("msg/{name}.msg"), m.msg_text()))
            .collect();
        files.push(("package.xml".into(), self.package_xml()));
        files.push(("CMakeLists.txt".into(), self.cmake_lists()));
        files
    }

    /// Write the files into `dir` (made if missing; files there of the same
    /// names are replaced); the paths written.
    pub fn write(&self, dir: &Path) -> Result<Vec<std::path::PathBuf>, PackageError> {
        let mut written = Vec::new();
        for (relative, text) in self.files() {
            let path = dir.join(relative);
            let made = path
                .parent()
                .map_or(Ok(()), std::fs::create_dir_all)
                .and_then(|()| std::fs::write(&path, text));
            made.map_err(|source| PackageError::Write {
                path: path.clone(),
                source,
            })?;
            written.push(path);
        }
        Ok(written)
    }

    fn package_xml(&self) -> String {
        let depends: String = self
            .depends
            .iter()
            .map(|d| format!("  <depend>{d}</depend>\n"))
            .collect();
        format!(
            r#"<?xml version="1.0"?>
<?xml-model href="http://download.ros.org/schema/package_format3.xsd" schematypens="http://www.w3.org/2001/XMLSchema"?>
<package format="3">
  <name>{name}</name>
  <version>0.1.0</version>
  <description>Messages of the embodied agents' buffers, as their ROS 2 bridge publishes and takes them (generated: do not edit).</description>
  <maintainer email="nobody@example.com">generated</maintainer>
  <license>MIT OR Apache-2.0</license>

  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
{depends}  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>

  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"#,
            name = self.name,
        )
    }

    fn cmake_lists(&self) -> String {
        let finds: String = self
            .depends
            .iter()
            .map(|d| format!("find_package({d} REQUIRED)\n"))
            .collect();
        let msgs: String = self
            .messages
            .keys()
            .map(|name| format!("  \"msg/{name}.msg\"\n"))
            .collect();
        let depends = if self.depends.is_empty() {
            String::new()
        } else {
            format!("  DEPENDENCIES {}\n", self.depends.join(" "))
        };
        format!(
            "cmake_minimum_required(VERSION 3.8)\n\
             project({name})\n\n\
             find_package(ament_cmake REQUIRED)\n\
             find_package(rosidl_default_generators REQUIRED)\n\
             {finds}\n\
             rosidl_generate_interfaces(${{PROJECT_NAME}}\n\
             {msgs}{depends})\n\n\
             ament_export_dependencies(rosidl_default_runtime)\n\
             ament_package()\n",
            name = self.name,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{Field, FieldType, Primitive};

    fn msg(package: &str, name: &str, fields: Vec<Field>) -> Message {
        Message::new(MsgName::new(package, name), fields)
    }

    #[test]
    fn own_messages_become_files_and_other_packages_dependencies() {
        let point = msg(
            "rex_msgs",
            "Point2",
            vec![Field::new("x", FieldType::primitive(Primitive::Float64))],
        );
        let stamp = msg("builtin_interfaces", "Time", Vec::new());
        let plan = msg(
            "rex_msgs",
            "Plan",
            vec![
                Field::new("points", FieldType::message(point.name.clone()).unbounded()),
                Field::new(
                    "stamp",
                    FieldType::message(MsgName::new("builtin_interfaces", "Time")),
                ),
            ],
        );
        let set = Messages {
            root: plan,
            referenced: vec![point.clone(), stamp],
        };
        let again = Messages {
            root: point,
            referenced: Vec::new(),
        };
        let package = Package::of("rex_msgs", [&set, &again]).unwrap();
        assert_eq!(package.depends(), ["builtin_interfaces"]);
        let files = package.files();
        let names: Vec<&str> = files.iter().map(|(p, _)| p.as_str()).collect();
        assert_eq!(
            names,
            [
                "msg/Plan.msg",
                "msg/Point2.msg",
                "package.xml",
                "CMakeLists.txt"
            ]
        );
        assert_eq!(
            files[0].1,
            "rex_msgs/Point2[] points\nbuiltin_interfaces/Time stamp\n"
        );
        let cmake = &files[3].1;
        assert!(cmake.contains("project(rex_msgs)\n"), "{cmake}");
        assert!(
            cmake.contains(
                "  \"msg/Plan.msg\"\n  \"msg/Point2.msg\"\n  DEPENDENCIES builtin_interfaces\n)"
            ),
            "{cmake}"
        );
        assert!(
            cmake.contains("find_package(builtin_interfaces REQUIRED)"),
            "{cmake}"
        );
        let xml = &files[2].1;
        assert!(
            xml.contains("<name>rex_msgs</name>")
                && xml.contains("<depend>builtin_interfaces</depend>")
        );
        assert!(xml.contains("<member_of_group>rosidl_interface_packages</member_of_group>"));
    }

    #[test]
    fn conflicting_definitions_and_empty_packages_are_refused() {
        let a = Messages {
            root: msg("p", "A", Vec::new()),
            referenced: Vec::new(),
        };
        let b = Messages {
            root: msg(
                "p",
                "A",
                vec![Field::new("x", FieldType::primitive(Primitive::Int8))],
            ),
            referenced: Vec::new(),
        };
        assert_eq!(
            Package::of("p", [&a, &b]).unwrap_err().to_string(),
            "two different definitions of `p/msg/A`"
        );
        assert_eq!(
            Package::of("q", [&a]).unwrap_err().to_string(),
            "no message of package `q`: nothing to build"
        );
    }
}
