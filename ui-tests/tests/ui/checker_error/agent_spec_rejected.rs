// The spec's arcs leave a gap: the checker's finding is the compile error.
embodied::agent!(spec = "lamp_gap.ron", agent = "house");

fn main() {}
