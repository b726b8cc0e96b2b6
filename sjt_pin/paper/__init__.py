"""The paper's simulations: experiments, figures, scenarios, the stability test, reproduce."""
