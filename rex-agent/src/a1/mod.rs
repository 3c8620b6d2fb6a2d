//! The locomotion agent `a1` of the paper's Fig. 3: the control subsystem [`c1`],
//! the virtual effector [`e11`] (e1,1) and the virtual receptor [`r11`] (r1,1), and
//! the free space they check plans and poses against ([`map`]). What their buffers
//! carry is [`crate::payload`]; the system that puts a1 in the simulated world is
//! [`crate::system`]: a1 knows nothing of the world.

pub mod c1;
pub mod e11;
pub mod map;
pub mod r11;
