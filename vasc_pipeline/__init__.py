"""vasc_pipeline: globally optimised arterial trees by simulated annealing (Keelan, Chung & Hague)."""
