"""Tournassoud, Lozano-Perez & Mazer (1987), "Regrasping": grasp classes, placement classes, the grasp-placement
table and backward chaining. Modules: features, classes, table, chaining, plans; only `stages` talks to the store."""
