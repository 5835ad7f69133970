"""What the pilot is told: the rendered prompts (render), their templates, and the context beyond the paper."""
