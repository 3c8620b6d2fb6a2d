// The spec names a buffer that does not exist.
embodied::agent!(spec = "lamp_typo.ron", agent = "house");

fn main() {}
