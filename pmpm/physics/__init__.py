"""Physics chosen by the scene: materials, loads and their time functions, boundary conditions,
multi-field contact and ground motion. Nothing here runs unless a scene names it."""
