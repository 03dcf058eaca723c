"""Physics of parts on the vibrating plate (PHYSICS.md): asymptotic fields and full dynamics."""
