"""Pure algorithms of the solver: no sockets, no printing, no global state (see STYLE.md)."""
