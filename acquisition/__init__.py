"""impactlab.acquisition: the analyser driver, transports, capture sessions and recordings."""
