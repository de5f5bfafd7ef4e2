//! The GPU context and the shader ABI, below the simulator (docs/design.md §11): the wgpu device and
//! its error handling (`context`), the Pod structs mirrored in WGSL (`layout`), the binding tables
//! (`bindings`), the shader sources (`shaders`), a burn tensor's wgpu buffer (`io`), why no
//! hardware adapter was found (`vulkan_probe`), what a driver's compiler makes of a kernel
//! (`shader_stats`) and where a GPU's time goes (`profile`).

pub mod bindings;
pub mod context;
pub mod io;
pub mod layout;
pub mod profile;
pub mod shader_stats;
pub mod shaders;
pub mod vulkan_probe;
