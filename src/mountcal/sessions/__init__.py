"""Sessions at the vehicle: plan one, run one live."""
