"""Max 1986 height-field clouds and the haze shafts below them."""
